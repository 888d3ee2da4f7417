"""The two clocks, stated once: the physics step and the control step; the substeps follow from them."""

from __future__ import annotations

PHYSICS_DT = 0.002
"""[s] one MuJoCo step (`opt.timestep`), as in the classic suite's model files."""

CONTROL_DT = 0.04
"""[s] one env step, the control period: 25 Hz. Observed velocities are multiplied by it, as in the
classic suite (it multiplies them by its dt, which is this)."""

N_SUBSTEPS = round(CONTROL_DT / PHYSICS_DT)
"""Physics steps per control step (20)."""

if abs(N_SUBSTEPS * PHYSICS_DT - CONTROL_DT) > 1e-12:
    raise ValueError(f"CONTROL_DT {CONTROL_DT} s is not a whole number of PHYSICS_DT {PHYSICS_DT} s steps")
