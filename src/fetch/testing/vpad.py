"""A virtual SDL game controller for tests: pygame and its SDL game-controller API see an Xbox-style pad."""

from __future__ import annotations

import ctypes
import re

import pygame

# SDL_GameControllerAxis / SDL_GameControllerButton order: a virtual pad of type "game controller"
# gets the default mapping, in which raw axis/button i is controller axis/button i.
AXES = {"leftx": 0, "lefty": 1, "rightx": 2, "righty": 3, "lefttrigger": 4, "righttrigger": 5}
BUTTONS = {"a": 0, "b": 1, "x": 2, "y": 3, "back": 4, "guide": 5, "start": 6, "leftstick": 7, "rightstick": 8,
           "leftshoulder": 9, "rightshoulder": 10, "dpup": 11, "dpdown": 12, "dpleft": 13, "dpright": 14}
_SDL_JOYSTICK_TYPE_GAMECONTROLLER = 1


def sdl_library() -> ctypes.CDLL:
    """The libSDL2 that pygame bundles (found in this process's memory map), so state is shared with pygame."""
    with open("/proc/self/maps", encoding="utf-8") as f:
        paths = sorted({line.split()[-1] for line in f if re.search(r"/libSDL2-2[^/]*\.so", line)})
    if not paths:
        raise RuntimeError("libSDL2 is not loaded in this process; import pygame first")
    lib = ctypes.CDLL(paths[0])
    lib.SDL_JoystickAttachVirtual.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int]
    lib.SDL_JoystickAttachVirtual.restype = ctypes.c_int
    lib.SDL_JoystickDetachVirtual.argtypes = [ctypes.c_int]
    lib.SDL_JoystickDetachVirtual.restype = ctypes.c_int
    lib.SDL_JoystickOpen.argtypes = [ctypes.c_int]
    lib.SDL_JoystickOpen.restype = ctypes.c_void_p
    lib.SDL_JoystickClose.argtypes = [ctypes.c_void_p]
    lib.SDL_JoystickClose.restype = None
    lib.SDL_JoystickInstanceID.argtypes = [ctypes.c_void_p]
    lib.SDL_JoystickInstanceID.restype = ctypes.c_int
    lib.SDL_NumJoysticks.argtypes = []
    lib.SDL_NumJoysticks.restype = ctypes.c_int
    lib.SDL_JoystickGetDeviceInstanceID.argtypes = [ctypes.c_int]
    lib.SDL_JoystickGetDeviceInstanceID.restype = ctypes.c_int
    lib.SDL_JoystickSetVirtualAxis.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int16]
    lib.SDL_JoystickSetVirtualAxis.restype = ctypes.c_int
    lib.SDL_JoystickSetVirtualButton.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_uint8]
    lib.SDL_JoystickSetVirtualButton.restype = ctypes.c_int
    lib.SDL_GetError.argtypes = []
    lib.SDL_GetError.restype = ctypes.c_char_p
    return lib


def init_headless() -> None:
    """pygame's display and joystick modules, as the gamepad needs them. Set SDL_VIDEODRIVER=dummy
    first (no window; the fixtures do it with monkeypatch, so it does not leak into other tests)."""
    pygame.display.init()
    pygame.joystick.init()


def _int16(value: float) -> int:
    return int(round(max(-1.0, min(1.0, value)) * 32767))


class VirtualPad:
    """An Xbox-layout pad attached to SDL: 6 axes, 15 buttons, 1 hat; `detach()` unplugs it."""

    def __init__(self) -> None:
        if not pygame.joystick.get_init():
            raise RuntimeError("call init_headless() (or pygame.joystick.init()) before attaching a virtual pad")
        self.sdl = sdl_library()
        self._handle: int | None = None
        self._device_index = -1
        self.attach()

    @property
    def attached(self) -> bool:
        return self._handle is not None

    def attach(self) -> None:
        """Plug the pad in (again): it starts centred, triggers released, no button pressed."""
        if self._handle is not None:
            return
        index = self.sdl.SDL_JoystickAttachVirtual(_SDL_JOYSTICK_TYPE_GAMECONTROLLER, 6, 15, 1)
        if index < 0:
            raise RuntimeError(f"SDL_JoystickAttachVirtual failed: {self.sdl.SDL_GetError().decode()}")
        handle = self.sdl.SDL_JoystickOpen(index)
        if not handle:
            raise RuntimeError(f"SDL_JoystickOpen failed: {self.sdl.SDL_GetError().decode()}")
        self._handle = handle
        self._instance = self.sdl.SDL_JoystickInstanceID(handle)
        self.set_stick(0.0, 0.0)
        self.set_triggers(0.0, 0.0)

    def detach(self) -> None:
        """Unplug the pad: SDL sends the device-removed events."""
        if self._handle is None:
            return
        index = next(i for i in range(self.sdl.SDL_NumJoysticks())
                     if self.sdl.SDL_JoystickGetDeviceInstanceID(i) == self._instance)
        self.sdl.SDL_JoystickClose(self._handle)
        self._handle = None
        if self.sdl.SDL_JoystickDetachVirtual(index) != 0:
            raise RuntimeError(f"SDL_JoystickDetachVirtual failed: {self.sdl.SDL_GetError().decode()}")

    def _require(self) -> int:
        if self._handle is None:
            raise RuntimeError("the virtual pad is detached")
        return self._handle

    def set_axis(self, axis: str | int, value: float) -> None:
        """Raw axis value in [-1, 1] (the game-controller API reads triggers -1..1 as 0..1)."""
        index = AXES[axis] if isinstance(axis, str) else axis
        self.sdl.SDL_JoystickSetVirtualAxis(self._require(), index, _int16(value))

    def set_stick(self, x: float, y: float) -> None:
        """Left stick, SDL convention: x right positive, y DOWN positive, in [-1, 1]."""
        self.set_axis("leftx", x)
        self.set_axis("lefty", y)

    def set_triggers(self, lt: float, rt: float) -> None:
        """Triggers pressed in [0, 1]."""
        self.set_axis("lefttrigger", 2.0 * lt - 1.0)
        self.set_axis("righttrigger", 2.0 * rt - 1.0)

    def press(self, button: str | int) -> None:
        self._set_button(button, 1)

    def release(self, button: str | int) -> None:
        self._set_button(button, 0)

    def _set_button(self, button: str | int, state: int) -> None:
        index = BUTTONS[button] if isinstance(button, str) else button
        self.sdl.SDL_JoystickSetVirtualButton(self._require(), index, state)

    def close(self) -> None:
        self.detach()
