"""The keyboard device, for people without a pad: keys held in the viewer window move the arm."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection, Mapping

import numpy as np

from fetch.teleop.devices import Command, rotate

MOVE_KEYS: dict[str, tuple[int, int, int]] = {
    "up": (0, 1, 0), "w": (0, 1, 0), "down": (0, -1, 0), "s": (0, -1, 0),
    "right": (1, 0, 0), "d": (1, 0, 0), "left": (-1, 0, 0), "a": (-1, 0, 0),
    "r": (0, 0, 1), "page up": (0, 0, 1), "f": (0, 0, -1), "page down": (0, 0, -1),
}
"""Held keys: (right, up in the view, z)."""
PRECISION_KEYS = ("left shift", "right shift")
GRIPPER_KEY, CAMERA_KEY, FINISH_KEYS, DISCARD_KEYS, QUIT_KEY = "space", "c", ("return", "enter"), ("backspace", "y"), \
    "escape"


@dataclasses.dataclass
class KeyboardState:
    gripper_closed: bool = False


def keyboard_command(held: Collection[str], pressed: Collection[str], state: KeyboardState, yaw: float = 0.0,
                     precision_scale: float = 0.3) -> Command:
    """The command for keys `held` now and keys `pressed` since the last tick (pygame key names)."""
    if GRIPPER_KEY in pressed:
        state.gripper_closed = not state.gripper_closed
    x = y = z = 0.0
    for key in held:
        if key in MOVE_KEYS:
            dx, dy, dz = MOVE_KEYS[key]
            x, y, z = x + dx, y + dy, z + dz
    x, y = rotate(float(np.clip(x, -1, 1)), float(np.clip(y, -1, 1)), yaw)
    precision = any(k in held for k in PRECISION_KEYS)
    scale = precision_scale if precision else 1.0
    action = np.clip(np.array([x * scale, y * scale, np.clip(z, -1, 1) * scale,
                               -1.0 if state.gripper_closed else 1.0], np.float32), -1.0, 1.0)
    return Command(action, discard=any(k in pressed for k in DISCARD_KEYS),
                   finish=any(k in pressed for k in FINISH_KEYS), quit=QUIT_KEY in pressed,
                   switch_camera=CAMERA_KEY in pressed, precision=precision)


class KeyboardDevice:
    """Reads the viewer window's keyboard (the viewer pumps the events each tick)."""

    name = "keyboard"

    def __init__(self, viewer: object, yaw: Callable[[], float] | None = None) -> None:
        import pygame

        self.pygame = pygame
        self.viewer = viewer
        self.yaw = yaw
        self.state = KeyboardState()
        self._codes = {name: pygame.key.key_code(name) for name in
                       [*MOVE_KEYS, *PRECISION_KEYS]}

    def reset(self) -> None:
        self.state = KeyboardState()

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        pg = self.pygame
        down = pg.key.get_pressed()
        held = [name for name, code in self._codes.items() if down[code]]
        pressed = [pg.key.name(code) for code in getattr(self.viewer, "key_events", [])]
        if getattr(self.viewer, "closed", False):
            pressed.append(QUIT_KEY)
        return keyboard_command(held, pressed, self.state, self.yaw() if self.yaw else 0.0)

    def close(self) -> None:
        pass
