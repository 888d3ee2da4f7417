"""Pad snapshots to commands: the pure part of the gamepad (no pygame), with the memory edges need."""

from __future__ import annotations

import dataclasses
import math

from fetch.teleop.devices import Command, HandControls, rotate
from fetch.teleop.gamepad.config import GamepadConfig


@dataclasses.dataclass(frozen=True)
class PadState:
    """One raw snapshot of a pad. Stick axes SDL-normalised in [-1, 1] (x right, y DOWN positive); triggers as
    read: in [0, 1] from the SDL GameController API, in [-1, 1] from a raw joystick axis. `held`: the
    `CONTROLS` roles whose buttons are down."""

    lx: float = 0.0
    ly: float = 0.0
    lt: float = 0.0
    rt: float = 0.0
    held: frozenset[str] = frozenset()


def radial_deadzone(x: float, y: float, deadzone: float) -> tuple[float, float]:
    """The stick (x, y) with a round dead zone of radius `deadzone`, rescaled so the output grows from 0 at
    the edge of the zone to 1 at full tilt (no jump); the direction is kept."""
    magnitude = math.hypot(x, y)
    if magnitude <= deadzone:
        return 0.0, 0.0
    scale = (min(magnitude, 1.0) - deadzone) / (1.0 - deadzone) / magnitude
    return x * scale, y * scale


class _Trigger:
    """A raw-index trigger to [0, 1]. Full-range triggers rest at -1 but many drivers report 0 until the first
    touch, which collect_fetch_demo.py's first rule read as half pressed (and its rule jumped at 0); here an untouched
    or not-yet-known trigger reads 0 and a full-range one maps linearly."""

    def __init__(self, mode: str) -> None:
        self.mode = mode
        self.forget()

    def forget(self) -> None:
        self.full_range = self.mode == "-1..1"
        self.touched = False

    def __call__(self, raw: float) -> float:
        if self.mode == "0..1":
            return min(max(raw, 0.0), 1.0)
        if raw != 0.0:
            self.touched = True
        if self.mode == "auto" and raw < -0.5:
            self.full_range = True
        if self.full_range:
            return min(max((raw + 1.0) / 2.0, 0.0), 1.0) if self.touched else 0.0
        return min(max(raw, 0.0), 1.0)


class Mapper:
    """Pad snapshots to commands: the pure part of the gamepad, with the memory that edges and toggles need.

    X toggles the gripper on press; Y (discard), START (quit), B (finish) and LB (camera switch) fire once per
    press; RB scales motion by `precision_scale` while held; BACK rewinds a second, and more while held.
    Action = float32 (dx, dy, dz = rt - lt, gripper), motion times `pos_scale` (the env clips the action to
    [-1, 1]).
    """

    def __init__(self, config: GamepadConfig) -> None:
        self.config = config
        self.controls = HandControls(config.gripper_open, config.gripper_close, config.precision_scale)
        self._previous: frozenset[str] | None = frozenset()
        self._raw_lt = _Trigger(config.trigger_range) if isinstance(config.axis("lt"), int) else None
        self._raw_rt = _Trigger(config.trigger_range) if isinstance(config.axis("rt"), int) else None

    @property
    def gripper_closed(self) -> bool:
        return self.controls.gripper_closed

    def reset(self) -> None:
        """A new attempt: the gripper opens."""
        self.controls.reset()

    def resync(self) -> None:
        """A pad was (re)connected: buttons already down fire nothing, and raw triggers are learnt again."""
        self._previous = None
        for trigger in (self._raw_lt, self._raw_rt):
            if trigger is not None:
                trigger.forget()

    def __call__(self, state: PadState, yaw: float = 0.0) -> Command:
        """The command for `state`. `yaw` [rad]: the stick's (x, y) is rotated by it about world +z, so with
        the view's yaw (`fetch.teleop.viewer.camera_yaw`) stick "up" moves the hand away from the viewer; 0 is the
        seed's world mapping (stick right = +x, up = +y)."""
        cfg = self.config
        pressed = state.held - self._previous if self._previous is not None else frozenset()
        self._previous = state.held
        x, y = radial_deadzone(state.lx, state.ly, cfg.deadzone)
        if cfg.invert_y:
            y = -y
        x, y = rotate(x, y, yaw)
        lt = self._raw_lt(state.lt) if self._raw_lt else min(max(state.lt, 0.0), 1.0)
        rt = self._raw_rt(state.rt) if self._raw_rt else min(max(state.rt, 0.0), 1.0)
        return self.controls.command((x, y, rt - lt), pressed, "precision" in state.held, cfg.pos_scale,
                                     rewinding="rewind" in state.held)
