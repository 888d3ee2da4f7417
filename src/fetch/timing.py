"""The two clocks, stated once: the physics step and the control step; the substeps follow from them.
And the clock a person's session keeps time by (`Clock`)."""

from __future__ import annotations

import time

PHYSICS_DT = 0.002
"""[s] one MuJoCo step (`opt.timestep`), as in the classic suite's model files."""

CONTROL_DT = 0.04
"""[s] one env step, the control period: 25 Hz. Observed velocities are multiplied by it, as in the
classic suite (it multiplies them by its dt, which is this)."""

N_SUBSTEPS = round(CONTROL_DT / PHYSICS_DT)
"""Physics steps per control step (20)."""

if abs(N_SUBSTEPS * PHYSICS_DT - CONTROL_DT) > 1e-12:
    raise ValueError(f"CONTROL_DT {CONTROL_DT} s is not a whole number of PHYSICS_DT {PHYSICS_DT} s steps")


class Clock:
    """Ticks on absolute deadlines (no drift); counts the ticks that started late."""

    def __init__(self, hz: float) -> None:
        self.period = 1.0 / hz if hz > 0 else 0.0
        self.next = time.perf_counter()
        self.late = 0
        self._restarted = False

    def restart(self) -> None:
        """Start over: the next `wait` returns at once, and the deadlines follow from then (what ran between,
        such as a reset and a frame shown, is the gap between attempts, not lateness)."""
        self._restarted = True

    def wait(self) -> float:
        """Sleep until the next deadline; returns the deadline [s, perf_counter]."""
        if not self.period:
            return time.perf_counter()
        now = time.perf_counter()
        if self._restarted:
            self._restarted = False
            self.next = now
        elif now - self.next > self.period:  # a whole period lost: start again rather than rush
            self.late += 1
            self.next = now
        deadline = self.next
        if now < deadline:
            time.sleep(deadline - now)
        self.next = deadline + self.period
        return deadline
