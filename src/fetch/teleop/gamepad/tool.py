"""`gym-fetch gamepad`: the live view of what a pad sends, and the guided calibration."""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from fetch.errors import FetchError
from fetch.teleop.devices import Command
from fetch.teleop.gamepad.backend import DISCONNECTED, GamepadDevice, RawReading, _Pad, gamepad_from_flags
from fetch.teleop.gamepad.config import (
    CONTROLS,
    OPTIONAL_CONTROLS,
    STICK_AXES,
    GamepadConfig,
    PadFlags,
    config_from_flags,
    legend,
)


@dataclasses.dataclass(frozen=True)
class PadToolRequest:
    """What `gym-fetch gamepad` asks for: the live view of the pad for `seconds` (0: until START or Ctrl-C),
    or with `calibrate` the guided calibration that writes the profile `out`."""

    pad: PadFlags = PadFlags()
    seconds: float = 0.0
    """[s]"""
    calibrate: bool = False
    out: str | os.PathLike[str] | None = None


def run_gamepad_tool(request: PadToolRequest) -> int:
    """`gym-fetch gamepad`: the live view or the calibration; the exit status."""
    if request.calibrate:
        if not request.out:
            raise FetchError("--calibrate needs --out PROFILE.json (the file to write)")
        return _run_calibration(request.pad, request.out)
    device = gamepad_from_flags(request.pad)
    try:
        return _live_view(device, float(request.seconds or 0.0), sys.stdout)
    finally:
        device.close()


def describe(reading: RawReading, command: Command) -> str:
    """One line: the pad's raw axes and buttons (SDL names when known) and the resulting command."""
    parts = ["axes " + " ".join(f"{v:+.2f}" for v in reading.axes)]
    down = [str(i) for i, b in enumerate(reading.buttons) if b]
    parts.append("buttons " + (",".join(down) or "-"))
    if any(h != (0, 0) for h in reading.hats):
        parts.append("hats " + " ".join(f"{h}" for h in reading.hats))
    if reading.named_axes:
        parts.append(" ".join(f"{n} {v:+.2f}" for n, v in reading.named_axes.items()))
        parts.append("pressed " + (",".join(sorted(reading.named_buttons)) or "-"))
    parts.append("action [" + " ".join(f"{v:+.2f}" for v in command.action) + "]")
    events = [n for n in ("discard", "finish", "quit", "switch_camera", "precision", "paused") if getattr(command, n)]
    if events:
        parts.append(" ".join(events))
    return " | ".join(parts)


def _live_view(device: GamepadDevice, seconds: float, out: Any) -> int:
    pad = device.pad
    out.write(f"{pad.name}{' (SDL game controller)' if pad.controller is not None else ' (raw joystick)'}; "
              f"START or Ctrl-C to stop\n" + "\n".join("  " + line for line in legend(device.config)) + "\n")
    out.flush()
    tty = bool(getattr(out, "isatty", lambda: False)())
    deadline = time.monotonic() + seconds if seconds > 0 else math.inf
    last = ""
    try:
        while time.monotonic() < deadline:
            command = device.poll()
            line = command.status if command.paused else describe(pad.raw(), command)
            if line != last:
                out.write(f"\r{line}\x1b[K" if tty else line + "\n")
                out.flush()
                last = line
            if command.quit:
                break
            time.sleep(0.02)
    except KeyboardInterrupt:
        pass
    if tty:
        out.write("\n")
    return 0


@dataclasses.dataclass(frozen=True)
class _Step:
    role: str
    instruction: str


CALIBRATION_STEPS = (
    _Step("lx", "push the LEFT STICK fully to the RIGHT, then let go"),
    _Step("ly", "push the LEFT STICK fully UP, then let go"),
    _Step("lt", "squeeze the LEFT TRIGGER (LT) fully, then let go"),
    _Step("rt", "squeeze the RIGHT TRIGGER (RT) fully, then let go"),
    *(_Step(role, f"press the button to {text} (Xbox: {default.upper()})")
      for role, (_, default, text) in CONTROLS.items()),
)


def calibrate(pad: _Pad, base: GamepadConfig, say: Callable[[str, str], None],
              timeout: float = 20.0, period: float = 0.01) -> GamepadConfig:
    """Map each control to the raw joystick index that moves when asked. `say(role, text)` asks the person
    (role "rest", a key of `STICK_AXES`/`CONTROLS`, or "release"); optional controls not pressed within
    `timeout` [s] stay unbound to raw indices (their default SDL name is kept)."""
    def read() -> tuple[np.ndarray, np.ndarray]:
        if not pad.update():
            raise FetchError(f"calibration: {DISCONNECTED}")
        r = pad.raw()
        return np.asarray(r.axes, dtype=np.float64), np.asarray(r.buttons, dtype=bool)

    def settle(seconds: float) -> tuple[np.ndarray, np.ndarray]:
        end = time.monotonic() + seconds
        axes, buttons = read()
        while time.monotonic() < end:
            time.sleep(period)
            axes, buttons = read()
        return axes, buttons

    say("rest", "let go of every control")
    rest, _ = settle(0.5)
    used_axes: set[int] = set()
    used_buttons: set[int] = set()
    changes: dict[str, Any] = {}
    released: dict[str, float] = {}
    for step in CALIBRATION_STEPS:
        say(step.role, step.instruction)
        end = time.monotonic() + timeout
        found: int | None = None
        peak = 0.0
        while found is None and time.monotonic() < end:
            axes, buttons = read()
            if step.role in STICK_AXES:
                moved = np.abs(axes - rest)
                moved[list(used_axes)] = 0.0
                if moved.size and moved.max() > 0.5:
                    found = int(moved.argmax())
                    peak = float(axes[found])
            else:
                down = [i for i in np.flatnonzero(buttons) if i not in used_buttons]
                if down:
                    found = int(down[0])
            time.sleep(period)
        if found is None:
            if step.role in OPTIONAL_CONTROLS:
                say("skipped", f"{step.role}: nothing pressed, keeping {base.button(step.role)!r}")
                continue
            raise FetchError(f"calibration: nothing moved within {timeout:g} s for: {step.instruction}")
        if step.role in STICK_AXES:
            used_axes.add(found)
            changes[STICK_AXES[step.role][0]] = found
            say("release", f"got axis {found}; let go")
            # follow the axis to its extreme, then wait until it has come back (the person let go)
            end = time.monotonic() + timeout
            while True:
                axes, _ = read()
                value = float(axes[found])
                if abs(value - rest[found]) > abs(peak - rest[found]):
                    peak = value
                if abs(value - peak) > 0.5 * abs(peak - rest[found]) + 0.25:
                    break
                if time.monotonic() > end:
                    raise FetchError(f"calibration: axis {found} did not come back; {step.instruction}")
                time.sleep(period)
            released[step.role] = float(settle(0.3)[0][found])
            if step.role == "ly":
                changes["invert_y"] = bool(peak < rest[found])  # SDL: up is negative, so negate it
        else:
            used_buttons.add(found)
            changes[CONTROLS[step.role][0]] = found
            say("release", f"got button {found}; let go")
            while read()[1][found]:
                time.sleep(period)
    ranges = {"-1..1" if released.get(t, 0.0) < -0.5 else "0..1" for t in ("lt", "rt")}
    changes["trigger_range"] = ranges.pop() if len(ranges) == 1 else "auto"
    return dataclasses.replace(base, **changes)


def _run_calibration(flags: PadFlags, out: str | os.PathLike[str]) -> int:
    base = config_from_flags(flags)
    pad = _Pad(base, any_pad=True)
    print(f"calibrating {pad.name!r}: do each thing when asked (Ctrl-C to abort; nothing is written)")

    def say(role: str, text: str) -> None:
        if text:
            print(f"  {text}", flush=True)

    try:
        config = calibrate(pad, base, say)
    except KeyboardInterrupt:
        print("aborted; no profile written", file=sys.stderr)
        return 130
    finally:
        pad.close()
    config.save_profile(out, pad=pad.name)
    print(f"wrote {out}; use it with --profile {out}")
    for line in legend(config):
        print("  " + line)
    return 0
