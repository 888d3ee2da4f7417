"""The pygame backend: one pad read through SDL, as a collection `Device`."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from fetch._environ import environ
from fetch._gl import has_display
from fetch.errors import FetchError
from fetch.teleop.devices import FRAMES, Command, DeviceContext, DeviceKind, idle
from fetch.teleop.gamepad.config import (
    AXES,
    BUTTONS,
    CONTROLS,
    OPTIONAL_CONTROLS,
    STICK_AXES,
    GamepadConfig,
    PadFlags,
    add_gamepad_arguments,
    config_from_flags,
)
from fetch.teleop.gamepad.mapping import Mapper, PadState

DISCONNECTED = "pad disconnected: plug it back in"
NO_PAD = ("no gamepad found: connect one (USB or Bluetooth) and try again, or collect with --device keyboard "
          "(keys in the viewer window), --device expert or --device scripted")
NO_PAD_HEADLESS = ("no gamepad found, and no display: connect a pad (USB or Bluetooth) and try again, or collect "
                   "with a device that works headless: --device expert (the task's scripted expert) or --device "
                   "scripted (events from --scripted-json); --device keyboard needs a display (it reads keys in "
                   "the viewer window; on a server, run under xvfb-run)")

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
        # Without the first hint SDL drops pad input while another window (a terminal) has the focus.
        # SDL reads hints when a subsystem starts: they are set for the import and the start only.
        with environ(SDL_JOYSTICK_ALLOW_BACKGROUND_EVENTS="1", PYGAME_HIDE_SUPPORT_PROMPT="1"):
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
            with environ(overwrite=True, SDL_VIDEODRIVER="dummy"):  # a headless session: for this init only
                pygame.display.init()
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

    def gripper_from(self, action: np.ndarray | None) -> None:
        self.mapper.controls.gripper_from(action)

    def poll(self, obs: Mapping[str, np.ndarray] | None = None) -> Command:
        if not self.pad.update():
            return Command(idle(), paused=True, status=DISCONNECTED)
        if self.pad.generation != self._generation:
            self._generation = self.pad.generation
            self.mapper.resync()
        return self.mapper(self.pad.state(), self.yaw() if self.yaw is not None else 0.0)

    def close(self) -> None:
        self.pad.close()


def gamepad_from_flags(flags: PadFlags, yaw: Callable[[], float] | None = None) -> GamepadDevice:
    """The pad its flags (`PadFlags`) describe, steering by `yaw` (None: the world's axes)."""
    return GamepadDevice(config_from_flags(flags), yaw)


def build_gamepad(context: DeviceContext) -> GamepadDevice:
    return gamepad_from_flags(context.options_for(PadFlags), yaw=context.yaw)


def add_collect_arguments(p: Any) -> None:
    """The collector's gamepad flags: collect_fetch_demo.py's (`PadFlags`), and which way the stick steers
    (--frame, which the session reads: the keyboard steers by it too)."""
    add_gamepad_arguments(p)
    p.add_argument("--frame", default="camera", choices=list(FRAMES),
                   help="camera (default): stick 'up' moves away from the viewer; world: stick up = the world's +y "
                        "whatever the view (collect_fetch_demo.py's mapping)")


KIND = DeviceKind(
    name="gamepad", human=True, aliases=("xbox",), add_arguments=add_collect_arguments, options=PadFlags,
    summary="an Xbox (or any SDL) game pad; xbox is another name for it",
    build=build_gamepad,
    legend=("left stick: move x/y", "RT/LT: up/down", "X: open/close gripper", "RB hold: precision",
            "BACK: rewind 1 s (hold: more)", "LB: camera", "F11: full screen", "B: keep attempt", "Y: discard",
            "START: quit"))
