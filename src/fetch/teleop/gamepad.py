"""The gamepad device: an Xbox (or any SDL game controller) pad drives the hand; the mapping is a pure function."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from fetch._gl import has_display
from fetch.errors import FetchError, UnknownNameError
from fetch.teleop.devices import Command, idle, rotate

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
}
OPTIONAL_CONTROLS = ("precision", "camera", "finish")
"""Controls a pad may lack (a raw-index pad SDL does not know leaves them unbound)."""

TRIGGER_RANGES = ("auto", "0..1", "-1..1")
DISCONNECTED = "pad disconnected: plug it back in"
NO_PAD = ("no gamepad found: connect one (USB or Bluetooth) and try again, or collect with --device keyboard "
          "(keys in the viewer window), --device expert or --device scripted")
NO_PAD_HEADLESS = ("no gamepad found, and no display: connect a pad (USB or Bluetooth) and try again, or collect "
                   "with a device that works headless: --device expert (the task's scripted expert) or --device "
                   "scripted (events from --scripted-json); --device keyboard needs a display (it reads keys in "
                   "the viewer window; on a server, run under xvfb-run)")
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
    an int = that raw joystick index (the seed's way); a str = another SDL GameController name."""

    deadzone: float = 0.10
    """Radial dead zone of the left stick, as a fraction of full tilt; the output is rescaled (continuous)."""
    pos_scale: float = 1.0
    invert_y: bool = True
    """SDL's y axis points down; True negates it, so pushing the stick up gives +y (the seed's default)."""
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
    touch, which the seed's rule read as half pressed (and its rule jumped at 0); here an untouched or
    not-yet-known trigger reads 0 and a full-range one maps linearly."""

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
    press; RB scales motion by `precision_scale` while held. Action = float32 (dx, dy, dz = rt - lt,
    gripper), motion times `pos_scale`, clipped to [-1, 1].
    """

    def __init__(self, config: GamepadConfig) -> None:
        self.config = config
        self.gripper_closed = False
        self._previous: frozenset[str] | None = frozenset()
        self._raw_lt = _Trigger(config.trigger_range) if isinstance(config.axis("lt"), int) else None
        self._raw_rt = _Trigger(config.trigger_range) if isinstance(config.axis("rt"), int) else None

    def reset(self) -> None:
        """A new attempt: the gripper opens."""
        self.gripper_closed = False

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
        if "gripper" in pressed:
            self.gripper_closed = not self.gripper_closed
        x, y = radial_deadzone(state.lx, state.ly, cfg.deadzone)
        if cfg.invert_y:
            y = -y
        x, y = rotate(x, y, yaw)
        lt = self._raw_lt(state.lt) if self._raw_lt else min(max(state.lt, 0.0), 1.0)
        rt = self._raw_rt(state.rt) if self._raw_rt else min(max(state.rt, 0.0), 1.0)
        precision = "precision" in state.held
        scale = cfg.pos_scale * (cfg.precision_scale if precision else 1.0)
        gripper = cfg.gripper_close if self.gripper_closed else cfg.gripper_open
        action = np.clip(np.array([x * scale, y * scale, (rt - lt) * scale, gripper]), -1.0, 1.0).astype(np.float32)
        return Command(action, discard="discard" in pressed, finish="finish" in pressed, quit="quit" in pressed,
                       switch_camera="camera" in pressed, precision=precision,
                       status="precision" if precision else "")


@dataclasses.dataclass(frozen=True)
class RawReading:
    """What a pad sends, for the live view: raw joystick axes in [-1, 1], buttons, hats; and by SDL name."""

    axes: tuple[float, ...]
    buttons: tuple[bool, ...]
    hats: tuple[tuple[int, int], ...]
    named_axes: dict[str, float]
    named_buttons: frozenset[str]


def _pad_events(pygame: Any) -> list[int]:
    names = ("JOYAXISMOTION", "JOYBALLMOTION", "JOYHATMOTION", "JOYBUTTONDOWN", "JOYBUTTONUP", "JOYDEVICEADDED",
             "JOYDEVICEREMOVED", "CONTROLLERAXISMOTION", "CONTROLLERBUTTONDOWN", "CONTROLLERBUTTONUP",
             "CONTROLLERDEVICEADDED", "CONTROLLERDEVICEREMOVED", "CONTROLLERDEVICEREMAPPED")
    return [getattr(pygame, n) for n in names if hasattr(pygame, n)]


class _Pad:
    """The pygame backend: one pad, opened through the SDL GameController API (and the raw joystick for
    raw-index bindings), reopened when it comes back after an unplug."""

    def __init__(self, config: GamepadConfig, any_pad: bool = False) -> None:
        # Without this hint SDL drops pad input while another window (a terminal) has the focus.
        os.environ.setdefault("SDL_JOYSTICK_ALLOW_BACKGROUND_EVENTS", "1")
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        try:
            import pygame
            from pygame._sdl2 import controller
        except ImportError as e:
            raise FetchError("the gamepad needs pygame-ce (pip install pygame-ce); or use --device keyboard") from e
        self.pygame, self.sdl_controller = pygame, controller
        self.config = config
        self.bindings = config.bindings()
        self.any_pad = any_pad
        self._init_pygame()
        self._events = _pad_events(pygame)
        self.controller: Any = None
        self.joystick: Any = None
        self.name = ""
        self.generation = 0
        self._count = -1
        self.problem = ""
        if not self._open():
            self.close()
            raise FetchError(self.problem or (NO_PAD if has_display() else NO_PAD_HEADLESS))

    def _init_pygame(self) -> None:
        pygame = self.pygame
        self._started = [m for m in (pygame.joystick, self.sdl_controller) if not m.get_init()]
        # pygame reads pad events only with the video subsystem up. With no display, SDL's dummy video
        # driver at once: probing the others has libwayland-client print "error: XDG_RUNTIME_DIR is
        # invalid or not set in the environment." to stderr before any message of ours.
        if not pygame.display.get_init() and (has_display() or os.environ.get("SDL_VIDEODRIVER")):
            try:
                pygame.display.init()
            except pygame.error:
                pass
        if not pygame.display.get_init():
            previous = os.environ.get("SDL_VIDEODRIVER")
            os.environ["SDL_VIDEODRIVER"] = "dummy"  # a headless session: for this init only
            try:
                pygame.display.init()
            finally:
                if previous is None:
                    del os.environ["SDL_VIDEODRIVER"]
                else:
                    os.environ["SDL_VIDEODRIVER"] = previous
        pygame.joystick.init()
        self.sdl_controller.init()
        pygame.event.pump()

    def _needs_controller(self) -> bool:
        required = [r for r, b in self.bindings.items() if r not in OPTIONAL_CONTROLS]
        return any(isinstance(self.bindings[r], str) for r in required)

    def _open(self) -> bool:
        """Open the first usable pad; False (with `problem` set) when there is none."""
        pygame, controller = self.pygame, self.sdl_controller
        self._count = pygame.joystick.get_count()
        self.problem = ""
        needs_controller = self._needs_controller() and not self.any_pad
        for index in range(self._count):
            is_controller = controller.is_controller(index)
            if needs_controller and not is_controller:
                name = pygame.joystick.Joystick(index).get_name()
                self.problem = (f"the pad {name!r} is not known to SDL as a game controller: map it with "
                                f"`gym-fetch gamepad --calibrate --out pad.json` and pass --profile pad.json, "
                                f"or give its raw indices (--axis-lx ... --button-start)")
                continue
            joystick = pygame.joystick.Joystick(index)
            problem = self._check_indices(joystick)
            if problem:
                self.problem = problem
                continue
            self.joystick = joystick
            self.controller = controller.Controller(index) if is_controller else None
            self.name = joystick.get_name()
            self.generation += 1
            return True
        return False

    def _check_indices(self, joystick: Any) -> str:
        counts = {"axis": joystick.get_numaxes(), "button": joystick.get_numbuttons()}
        for role, binding in self.bindings.items():
            kind = "axis" if role in STICK_AXES else "button"
            if isinstance(binding, int) and binding >= counts[kind]:
                return (f"{role} is bound to raw {kind} {binding} but the pad {joystick.get_name()!r} has "
                        f"{counts[kind]} {'axes' if kind == 'axis' else 'buttons'} (0..{counts[kind] - 1})")
        return ""

    def _drop(self) -> None:
        if self.controller is not None:
            self.controller.quit()
        self.controller = self.joystick = None

    @property
    def connected(self) -> bool:
        return self.joystick is not None

    def update(self) -> bool:
        """Pump SDL, notice unplugs and re-plugs; True when a pad is connected. Only joystick and controller
        events are taken from the queue, so a window that reads its own events each tick is unaffected."""
        events = self.pygame.event.get(eventtype=self._events)
        removed = any(e.type in (self.pygame.JOYDEVICEREMOVED, self.pygame.CONTROLLERDEVICEREMOVED) for e in events)
        count = self.pygame.joystick.get_count()
        if self.connected and (removed or count != self._count) and not self._still_attached():
            self._drop()
        self._count = count
        if not self.connected and count > 0:
            self._open()
        return self.connected

    def _still_attached(self) -> bool:
        if self.controller is not None:
            return bool(self.controller.attached())
        instance = self.joystick.get_instance_id()
        return any(self.pygame.joystick.Joystick(i).get_instance_id() == instance
                   for i in range(self.pygame.joystick.get_count()))

    def _axis(self, binding: int | str) -> float:
        if isinstance(binding, int):
            return float(self.joystick.get_axis(binding))
        if self.controller is None:
            return 0.0
        return max(-1.0, min(1.0, self.controller.get_axis(AXES[binding]) / 32767.0))

    def _button(self, binding: int | str) -> bool:
        if isinstance(binding, int):
            return bool(self.joystick.get_button(binding))
        return self.controller is not None and bool(self.controller.get_button(BUTTONS[binding]))

    def state(self) -> PadState:
        """The current snapshot (call `update()` first)."""
        b = self.bindings
        held = frozenset(role for role in CONTROLS if self._button(b[role]))
        return PadState(self._axis(b["lx"]), self._axis(b["ly"]), self._axis(b["lt"]), self._axis(b["rt"]), held)

    def raw(self) -> RawReading:
        j = self.joystick
        named_axes = {n: self._axis(n) for n in AXES} if self.controller is not None else {}
        named_buttons = frozenset(n for n in BUTTONS if self.controller is not None and self._button(n))
        return RawReading(tuple(float(j.get_axis(i)) for i in range(j.get_numaxes())),
                          tuple(bool(j.get_button(i)) for i in range(j.get_numbuttons())),
                          tuple(tuple(j.get_hat(i)) for i in range(j.get_numhats())), named_axes, named_buttons)

    def close(self) -> None:
        self._drop()
        for module in reversed(self._started):  # only what we started: a viewer may still use pygame
            module.quit()
        self._started = []


class GamepadDevice:
    """A game pad as a `Device`. Raises FetchError when no pad is connected; an unplugged pad pauses the
    attempt (`Command.paused`) until it is plugged back in."""

    name = "gamepad"

    def __init__(self, config: GamepadConfig | None = None, yaw: Callable[[], float] | None = None) -> None:
        self.config = config or GamepadConfig()
        self.yaw = yaw
        self.mapper = Mapper(self.config)
        self.pad = _Pad(self.config)
        self._generation = 0  # the first poll resyncs: buttons already down when the pad opens fire nothing

    def reset(self) -> None:
        self.mapper.reset()

    def poll(self, obs: Mapping[str, np.ndarray] | None = None) -> Command:
        if not self.pad.update():
            return Command(idle(), paused=True, status=DISCONNECTED)
        if self.pad.generation != self._generation:
            self._generation = self.pad.generation
            self.mapper.resync()
        return self.mapper(self.pad.state(), self.yaw() if self.yaw is not None else 0.0)

    def close(self) -> None:
        self.pad.close()


def config_from_args(args: argparse.Namespace) -> GamepadConfig:
    """The config of the seed's flags, on top of `args.profile` if given; a flag left at its default value
    does not override the profile."""
    profile = getattr(args, "profile", None)
    base = GamepadConfig.from_profile(profile) if profile else GamepadConfig()
    defaults = GamepadConfig()
    changes: dict[str, Any] = {}
    for field in ("deadzone", "pos_scale", "invert_y", "gripper_open", "gripper_close", "precision_scale"):
        value = getattr(args, field, None)
        if value is not None and value != getattr(defaults, field):
            changes[field] = value
    for field in ("axis_lx", "axis_ly", "axis_lt", "axis_rt", "button_x", "button_y", "button_start"):
        value = getattr(args, field, None)
        if value is not None:
            changes[field] = value
    return dataclasses.replace(base, **changes)


def gamepad_from_args(args: argparse.Namespace, yaw: Callable[[], float] | None = None) -> GamepadDevice:
    return GamepadDevice(config_from_args(args), yaw)


def legend(config: GamepadConfig) -> list[str]:
    """The controls, one line each, for a HUD or a terminal."""
    def label(binding: int | str, kind: str) -> str:
        return f"raw {kind} {binding}" if isinstance(binding, int) else binding.upper()

    lines = [f"{label(config.axis('lx'), 'axis')}/{label(config.axis('ly'), 'axis')}: move the hand in x/y",
             f"{label(config.axis('rt'), 'axis')} - {label(config.axis('lt'), 'axis')}: move the hand up/down"]
    lines += [f"{label(config.button(r), 'button')}: {text}" for r, (_, _, text) in CONTROLS.items()]
    return lines


# ---- `gym-fetch gamepad`: the live view and the calibration ----


def add_gamepad_arguments(p: argparse.ArgumentParser | Any) -> None:
    """The seed's gamepad flags (same names and meaning) plus --profile and --precision-scale."""
    p.add_argument("--profile", default=None,
                   help="a mapping profile written by `gym-fetch gamepad --calibrate` (default: none)")
    p.add_argument("--deadzone", type=float, default=0.10,
                   help="radial dead zone of the left stick, a fraction of full travel (default 0.10)")
    p.add_argument("--pos-scale", type=float, default=1.0,
                   help="multiplies the stick's motion command (default 1.0: full speed)")
    p.add_argument("--precision-scale", type=float, default=0.3,
                   help="motion scale while precision (RB) is held (default 0.3)")
    p.add_argument("--invert-y", dest="invert_y", action="store_true", default=True,
                   help="stick up moves forward (SDL reports up as negative; default on, the seed's)")
    p.add_argument("--no-invert-y", dest="invert_y", action="store_false", help="stick up moves backward")
    p.add_argument("--gripper-open", type=float, default=1.0, help="a[3] sent to open the fingers (default 1.0)")
    p.add_argument("--gripper-close", type=float, default=-1.0,
                   help="a[3] sent to close the fingers (default -1.0)")
    for flag in ("--axis-lx", "--axis-ly", "--axis-lt", "--axis-rt", "--button-x", "--button-y", "--button-start"):
        p.add_argument(flag, type=int, default=None, help="raw joystick index (default: the SDL layout's)")


def add_gamepad_parser(subparsers: Any) -> argparse.ArgumentParser:
    """The `gamepad` subcommand: live view of the pad, or a guided calibration that writes a profile."""
    p: argparse.ArgumentParser = subparsers.add_parser(
        "gamepad", help="show what the pad sends (axes, buttons, the action), or calibrate it (--calibrate)")
    add_gamepad_arguments(p)
    p.add_argument("--seconds", type=float, default=0.0,
                   help="stop after this long [s] (default 0: until START or Ctrl-C)")
    p.add_argument("--calibrate", action="store_true", help="guided mapping of each control; needs --out")
    p.add_argument("--out", default=None, help="the profile file --calibrate writes (JSON)")
    p.set_defaults(run=run_gamepad_tool)
    return p


def run_gamepad_tool(args: argparse.Namespace) -> int:
    if args.calibrate:
        if not args.out:
            raise FetchError("--calibrate needs --out PROFILE.json (the file to write)")
        return _run_calibration(args)
    device = gamepad_from_args(args)
    try:
        return _live_view(device, float(getattr(args, "seconds", 0.0) or 0.0), sys.stdout)
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


def _run_calibration(args: argparse.Namespace) -> int:
    base = config_from_args(args)
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
    config.save_profile(args.out, pad=pad.name)
    print(f"wrote {args.out}; use it with --profile {args.out}")
    for line in legend(config):
        print("  " + line)
    return 0
