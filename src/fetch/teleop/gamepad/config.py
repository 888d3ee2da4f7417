"""The pad's layout and settings: SDL names, the bindings of each role, profiles, the flags."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from typing import Any

from fetch.errors import FetchError, UnknownNameError

# The SDL GameController layout (SDL_GameControllerAxis / SDL_GameControllerButton), by the names SDL's
# mapping strings use. An Xbox pad has this layout on Linux, Windows and macOS.
AXES = {"leftx": 0, "lefty": 1, "rightx": 2, "righty": 3, "lefttrigger": 4, "righttrigger": 5}
BUTTONS = {"a": 0, "b": 1, "x": 2, "y": 3, "back": 4, "guide": 5, "start": 6, "leftstick": 7, "rightstick": 8,
           "leftshoulder": 9, "rightshoulder": 10, "dpup": 11, "dpdown": 12, "dpleft": 13, "dpright": 14}

Binding = int | str | None
"""A control's source: an SDL GameController name ("leftx", "x", ...), a raw joystick index, or None (default)."""

# role -> (config field, default binding, what it does). The one table of the layout: profiles, the
# calibration and the legend all read it.
STICK_AXES = {
    "lx": ("axis_lx", "leftx", "move the hand left/right"),
    "ly": ("axis_ly", "lefty", "move the hand forward/back"),
    "lt": ("axis_lt", "lefttrigger", "move the hand down"),
    "rt": ("axis_rt", "righttrigger", "move the hand up"),
}
CONTROLS = {
    "gripper": ("button_x", "x", "toggle the gripper"),
    "discard": ("button_y", "y", "end the attempt and discard it"),
    "quit": ("button_start", "start", "quit the session"),
    "precision": ("button_precision", "rightshoulder", "hold for slow, precise motion"),
    "camera": ("button_camera", "leftshoulder", "switch the camera view"),
    "finish": ("button_finish", "b", "end the attempt and keep it if it succeeded"),
    "rewind": ("button_rewind", "back", "rewind the attempt one second (held: keep going back)"),
}
OPTIONAL_CONTROLS = ("precision", "camera", "finish", "rewind")
"""Controls a pad may lack (a raw-index pad SDL does not know leaves them unbound)."""

TRIGGER_RANGES = ("auto", "0..1", "-1..1")
_PROFILE_FORMAT = "gym-fetch gamepad profile"
_SCALARS = ("deadzone", "pos_scale", "invert_y", "gripper_open", "gripper_close", "precision_scale", "trigger_range")


def _check_binding(field: str, value: object, names: Mapping[str, int]) -> None:
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int | str):
        raise FetchError(f"{field} must be a raw index (int >= 0) or an SDL name, got {value!r}")
    if isinstance(value, int) and value < 0:
        raise FetchError(f"{field} must be a raw index >= 0, got {value}")
    if isinstance(value, str) and value not in names:
        raise UnknownNameError(f"{field} name", value, tuple(names))


@dataclasses.dataclass(frozen=True)
class GamepadConfig:
    """How a pad drives the hand. Bindings: None = the SDL GameController layout (`STICK_AXES`, `CONTROLS`);
    an int = that raw joystick index (collect_fetch_demo.py's way); a str = another SDL GameController name."""

    deadzone: float = 0.10
    """Radial dead zone of the left stick, as a fraction of full tilt; the output is rescaled (continuous)."""
    pos_scale: float = 1.0
    invert_y: bool = True
    """SDL's y axis points down; True negates it, so pushing the stick up gives +y (collect_fetch_demo.py's default)."""
    gripper_open: float = 1.0
    gripper_close: float = -1.0
    precision_scale: float = 0.3
    """Motion is multiplied by this while the precision button is held."""
    trigger_range: str = "auto"
    """Raw-index triggers only: "0..1", "-1..1" (rest at -1), or "auto" (-1..1 once it has read below -0.5)."""
    axis_lx: Binding = None
    axis_ly: Binding = None
    axis_lt: Binding = None
    axis_rt: Binding = None
    button_x: Binding = None
    button_y: Binding = None
    button_start: Binding = None
    button_precision: Binding = None
    button_camera: Binding = None
    button_finish: Binding = None
    button_rewind: Binding = None

    def __post_init__(self) -> None:
        for name in ("deadzone", "pos_scale", "gripper_open", "gripper_close", "precision_scale"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise FetchError(f"{name} must be a finite number, got {value!r}")
        if not 0.0 <= self.deadzone < 1.0:
            raise FetchError(f"deadzone must be in [0, 1), got {self.deadzone}")
        if self.pos_scale <= 0:
            raise FetchError(f"pos_scale must be > 0, got {self.pos_scale}")
        if not 0.0 < self.precision_scale <= 1.0:
            raise FetchError(f"precision_scale must be in (0, 1], got {self.precision_scale}")
        for name in ("gripper_open", "gripper_close"):
            if not -1.0 <= getattr(self, name) <= 1.0:
                raise FetchError(f"{name} must be in [-1, 1], got {getattr(self, name)}")
        if not isinstance(self.invert_y, bool):
            raise FetchError(f"invert_y must be true or false, got {self.invert_y!r}")
        if self.trigger_range not in TRIGGER_RANGES:
            raise UnknownNameError("trigger_range", self.trigger_range, TRIGGER_RANGES)
        for field, _, _ in STICK_AXES.values():
            _check_binding(field, getattr(self, field), AXES)
        for field, _, _ in CONTROLS.values():
            _check_binding(field, getattr(self, field), BUTTONS)

    def axis(self, role: str) -> int | str:
        """The binding of axis `role` ("lx", "ly", "lt", "rt"), defaults resolved."""
        field, default, _ = STICK_AXES[role]
        value = getattr(self, field)
        return default if value is None else value

    def button(self, role: str) -> int | str:
        """The binding of control `role` (a key of `CONTROLS`), defaults resolved."""
        field, default, _ = CONTROLS[role]
        value = getattr(self, field)
        return default if value is None else value

    def bindings(self) -> dict[str, int | str]:
        return {**{r: self.axis(r) for r in STICK_AXES}, **{r: self.button(r) for r in CONTROLS}}

    @classmethod
    def from_profile(cls, path: str | os.PathLike[str]) -> GamepadConfig:
        """The config a JSON profile (written by `save_profile` or `gym-fetch gamepad --calibrate`) describes."""
        try:
            with open(path, encoding="utf-8") as f:
                raw = json.load(f)
        except OSError as e:
            raise FetchError(f"cannot read the gamepad profile {path}: {e.strerror}") from e
        except json.JSONDecodeError as e:
            raise FetchError(f"gamepad profile {path} is not valid JSON: {e.msg} at line {e.lineno} "
                             f"column {e.colno}") from e
        try:
            return cls._from_dict(raw)
        except FetchError as e:
            raise FetchError(f"gamepad profile {path}: {e}") from e

    @classmethod
    def _from_dict(cls, raw: object) -> GamepadConfig:
        if not isinstance(raw, dict):
            raise FetchError(f"must hold a JSON object, not a {type(raw).__name__}")
        valid = {"format", "version", "pad", "axes", "buttons", *_SCALARS}
        unknown = set(raw) - valid
        if unknown:
            raise FetchError(f"unknown keys {sorted(unknown)}; valid: {sorted(valid)}")
        if raw.get("format", _PROFILE_FORMAT) != _PROFILE_FORMAT or raw.get("version", 1) != 1:
            raise FetchError(f"is not a version 1 {_PROFILE_FORMAT!r} (format {raw.get('format')!r}, "
                             f"version {raw.get('version')!r})")
        kwargs: dict[str, Any] = {k: raw[k] for k in _SCALARS if k in raw}
        for section, table in (("axes", STICK_AXES), ("buttons", CONTROLS)):
            entries = raw.get(section, {})
            if not isinstance(entries, dict):
                raise FetchError(f"\"{section}\" must be an object like {{\"{next(iter(table))}\": 0}}")
            unknown = set(entries) - set(table)
            if unknown:
                raise FetchError(f"unknown {section} {sorted(unknown)}; valid: {sorted(table)}")
            for role, value in entries.items():
                kwargs[table[role][0]] = value
        return cls(**kwargs)

    def save_profile(self, path: str | os.PathLike[str], pad: str = "") -> None:
        """Write this config as a JSON profile (every binding explicit, so it reads as the full layout)."""
        data: dict[str, Any] = {"format": _PROFILE_FORMAT, "version": 1}
        if pad:
            data["pad"] = pad
        data.update({k: getattr(self, k) for k in _SCALARS})
        data["axes"] = {r: self.axis(r) for r in STICK_AXES}
        data["buttons"] = {r: self.button(r) for r in CONTROLS}
        with open(path, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=2)
            f.write("\n")


@dataclasses.dataclass(frozen=True)
class PadFlags:
    """The pad's flags as given (`add_gamepad_arguments`: collect_fetch_demo.py's, plus --profile and
    --precision-scale); `config_from_flags` lays them over the profile. The gamepad device's options."""

    profile: str | None = None
    """a profile written by `gym-fetch gamepad --calibrate` (None: none)."""
    deadzone: float = GamepadConfig.deadzone
    pos_scale: float = GamepadConfig.pos_scale
    precision_scale: float = GamepadConfig.precision_scale
    invert_y: bool = GamepadConfig.invert_y
    gripper_open: float = GamepadConfig.gripper_open
    gripper_close: float = GamepadConfig.gripper_close
    axis_lx: int | None = None
    """raw joystick indices (None: the SDL layout's, or the profile's)."""
    axis_ly: int | None = None
    axis_lt: int | None = None
    axis_rt: int | None = None
    button_x: int | None = None
    button_y: int | None = None
    button_start: int | None = None


def config_from_flags(flags: PadFlags) -> GamepadConfig:
    """The config of collect_fetch_demo.py's pad flags, on top of `flags.profile` if given; a flag left at its
    default value does not override the profile."""
    base = GamepadConfig.from_profile(flags.profile) if flags.profile else GamepadConfig()
    defaults = GamepadConfig()
    changes: dict[str, Any] = {}
    for field in ("deadzone", "pos_scale", "invert_y", "gripper_open", "gripper_close", "precision_scale"):
        value = getattr(flags, field)
        if value is not None and value != getattr(defaults, field):
            changes[field] = value
    for field in ("axis_lx", "axis_ly", "axis_lt", "axis_rt", "button_x", "button_y", "button_start"):
        value = getattr(flags, field)
        if value is not None:
            changes[field] = value
    return dataclasses.replace(base, **changes)


def legend(config: GamepadConfig) -> list[str]:
    """The controls, one line each, for a HUD or a terminal."""
    def label(binding: int | str, kind: str) -> str:
        return f"raw {kind} {binding}" if isinstance(binding, int) else binding.upper()

    lines = [f"{label(config.axis('lx'), 'axis')}/{label(config.axis('ly'), 'axis')}: move the hand in x/y",
             f"{label(config.axis('rt'), 'axis')} - {label(config.axis('lt'), 'axis')}: move the hand up/down"]
    lines += [f"{label(config.button(r), 'button')}: {text}" for r, (_, _, text) in CONTROLS.items()]
    return lines


def add_gamepad_arguments(p: Any) -> None:
    """collect_fetch_demo.py's gamepad flags (same names and meaning) plus --profile and --precision-scale, added to
    a parser or group of the command layer; each flag's destination is a field of `PadFlags`."""
    p.add_argument("--profile", default=None,
                   help="a mapping profile written by `gym-fetch gamepad --calibrate` (default: none)")
    p.add_argument("--deadzone", type=float, default=0.10,
                   help="radial dead zone of the left stick, a fraction of full travel (default 0.10)")
    p.add_argument("--pos-scale", type=float, default=1.0,
                   help="multiplies the stick's motion command (default 1.0: full speed)")
    p.add_argument("--precision-scale", type=float, default=0.3,
                   help="motion scale while precision (RB) is held (default 0.3)")
    p.add_argument("--invert-y", dest="invert_y", action="store_true", default=True,
                   help="stick up moves forward (SDL reports up as negative; default on, as in collect_fetch_demo.py)")
    p.add_argument("--no-invert-y", dest="invert_y", action="store_false", help="stick up moves backward")
    p.add_argument("--gripper-open", type=float, default=1.0, help="a[3] sent to open the fingers (default 1.0)")
    p.add_argument("--gripper-close", type=float, default=-1.0,
                   help="a[3] sent to close the fingers (default -1.0)")
    for flag in ("--axis-lx", "--axis-ly", "--axis-lt", "--axis-rt", "--button-x", "--button-y", "--button-start"):
        p.add_argument(flag, type=int, default=None, help="raw joystick index (default: the SDL layout's)")
