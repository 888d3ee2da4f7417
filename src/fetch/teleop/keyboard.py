"""The keyboard device, for people without a pad: keys held in the viewer window move the arm."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

from fetch.errors import FetchError
from fetch.teleop.devices import Command, DeviceContext, DeviceKind, HandControls, rotate

MOVE_KEYS: dict[str, tuple[int, int, int]] = {
    "up": (0, 1, 0), "w": (0, 1, 0), "down": (0, -1, 0), "s": (0, -1, 0),
    "right": (1, 0, 0), "d": (1, 0, 0), "left": (-1, 0, 0), "a": (-1, 0, 0),
    "r": (0, 0, 1), "page up": (0, 0, 1), "f": (0, 0, -1), "page down": (0, 0, -1),
}
"""Held keys: (right, up in the view, z)."""
PRECISION_KEYS = ("left shift", "right shift")
GRIPPER_KEY, CAMERA_KEY, FINISH_KEYS, DISCARD_KEYS, QUIT_KEY, REWIND_KEY = "space", "c", ("return", "enter"), \
    ("backspace", "y"), "escape", "z"


def keyboard_command(held: Collection[str], pressed: Collection[str], controls: HandControls,
                     yaw: float = 0.0) -> Command:
    """The command for keys `held` now and keys `pressed` since the last tick (pygame key names)."""
    x = y = z = 0.0
    for key in held:
        if key in MOVE_KEYS:
            dx, dy, dz = MOVE_KEYS[key]
            x, y, z = x + dx, y + dy, z + dz
    x, y = rotate(min(max(x, -1.0), 1.0), min(max(y, -1.0), 1.0), yaw)
    roles = {role for role, keys in _ROLE_KEYS.items() if any(k in pressed for k in keys)}
    return controls.command((x, y, min(max(z, -1.0), 1.0)), roles, any(k in held for k in PRECISION_KEYS),
                            rewinding=REWIND_KEY in held)


_ROLE_KEYS = {"gripper": (GRIPPER_KEY,), "camera": (CAMERA_KEY,), "finish": FINISH_KEYS, "discard": DISCARD_KEYS,
              "quit": (QUIT_KEY,), "rewind": (REWIND_KEY,)}


class KeyboardDevice:
    """Reads the viewer window's keyboard (the viewer pumps the events each tick)."""

    name = "keyboard"

    def __init__(self, viewer: object, yaw: Any = None) -> None:
        import pygame

        self.pygame = pygame
        self.viewer = viewer
        self.yaw = yaw
        self.controls = HandControls()
        self._codes = {name: pygame.key.key_code(name) for name in
                       [*MOVE_KEYS, *PRECISION_KEYS, REWIND_KEY]}

    def reset(self) -> None:
        self.controls.reset()

    def gripper_from(self, action: np.ndarray | None) -> None:
        self.controls.gripper_from(action)

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        pg = self.pygame
        down = pg.key.get_pressed()
        held = [name for name, code in self._codes.items() if down[code]]
        pressed = [pg.key.name(code) for code in getattr(self.viewer, "key_events", [])]
        if getattr(self.viewer, "closed", False):
            pressed.append(QUIT_KEY)
        return keyboard_command(held, pressed, self.controls, self.yaw() if self.yaw else 0.0)

    def close(self) -> None:
        pass


def build_keyboard(context: DeviceContext) -> KeyboardDevice:
    if context.viewer is None:
        raise FetchError("--device keyboard reads keys typed into the collection window, and none is open: "
                         "collect with the window (--render auto or human, on a display or under xvfb-run), or "
                         "with a device that needs none: --device expert, scripted or gamepad")
    return KeyboardDevice(context.viewer, context.yaw)


KIND = DeviceKind(
    name="keyboard", human=True, add_arguments=None, build=build_keyboard, reads_window=True,
    summary="keys in the viewer window (needs a display)",
    legend=("arrows / WASD: move x/y", "R/F: up/down", "SPACE: open/close gripper", "SHIFT hold: precision",
            "Z: rewind 1 s (hold: more)", "C: camera", "F11: full screen", "ENTER: keep attempt",
            "BACKSPACE: discard", "ESC: quit"))
