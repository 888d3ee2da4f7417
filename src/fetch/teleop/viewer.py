"""The collection window: the scene from a switchable camera, a heads-up display and the controls legend.

It is a pygame window showing MuJoCo's offscreen rendering, so the same event loop serves the window,
the keyboard and the gamepad. pygame is imported here only, when a window is asked for.
"""

from __future__ import annotations

import collections
import math
import os
import time
from typing import Any

import mujoco

from fetch.errors import FetchError
from fetch.rendering import OffscreenRenderer
from fetch.teleop.session import HudState

CAMERAS = ("front", "side", "behind", "wrist")
MAX_FRAME_GAP = 0.5
"""[s] draw at least this often, even if a frame then delays a control tick."""
LEGEND = {
    "gamepad": ("left stick: move x/y   RT/LT: up/down   X: open/close gripper",
                "RB hold: precision   LB: camera   B: keep attempt   Y: discard   START: quit"),
    "keyboard": ("arrows / WASD: move x/y   R/F: up/down   SPACE: open/close gripper",
                 "SHIFT hold: precision   C: camera   ENTER: keep attempt   BACKSPACE: discard   ESC: quit"),
}


def camera_yaw(model: mujoco.MjModel, data: mujoco.MjData, camera: str) -> float:
    """[rad] The rotation from the seed's fixed stick mapping (stick up = world +y) to the camera's:
    stick up then moves the hand away from the viewer, along the camera's view on the table."""
    cam = model.camera(camera).id
    forward = -data.cam_xmat[cam].reshape(3, 3)[:, 2]  # a camera looks along its -z axis
    if math.hypot(forward[0], forward[1]) < 1e-6:  # looking straight down: use its image up
        forward = data.cam_xmat[cam].reshape(3, 3)[:, 1]
    return math.atan2(-forward[0], forward[1])


class Viewer:
    """A window on the env: `show(hud)` once per tick draws the scene and the HUD and reads input.

    Keys pressed since the last `show` are in `key_events` (pygame key codes), the window's close
    button sets `closed`. Raises FetchError when no window can be opened (no display).
    """

    def __init__(self, env: Any, device_name: str, size: tuple[int, int] = (640, 480),
                 camera: str = "front") -> None:
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) \
                and os.environ.get("SDL_VIDEODRIVER") not in ("dummy", "offscreen"):
            raise FetchError("no display for the viewer window; use --render none (headless), or run under "
                             "a desktop session or `xvfb-run`")
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame

        self.pygame = pygame
        self.env = env.unwrapped
        self.size = size
        # The GL context first: with MUJOCO_GL=egl, a context made after SDL opened its X11 window
        # fails (EGL_BAD_ACCESS).
        self.renderer = OffscreenRenderer(self.env.model, size[0], size[1], simple=True)
        pygame.display.init()
        pygame.font.init()
        try:
            self.window = pygame.display.set_mode(size)
        except pygame.error as e:
            raise FetchError(f"cannot open the viewer window: {e}; use --render none") from e
        pygame.display.set_caption(f"gym-fetch-v2: {self.env.spec.id if self.env.spec else 'collect'}")
        self.font = pygame.font.Font(None, 22)
        self.cameras = [c for c in CAMERAS if c in {self.env.model.camera(i).name for i in range(self.env.model.ncam)}]
        if camera not in self.cameras:
            raise FetchError(f"unknown camera {camera!r}; known: {', '.join(self.cameras)}")
        self.camera = camera
        self.legend = LEGEND.get(device_name, ())
        self.key_events: list[int] = []
        self.closed = False
        self.frames = 0
        self.ticks = 0
        self._frame_costs: collections.deque[float] = collections.deque([0.0], maxlen=8)
        self._last_frame = 0.0

    def yaw(self) -> float:
        return camera_yaw(self.env.model, self.env.data, self.camera)

    def next_camera(self) -> None:
        self.camera = self.cameras[(self.cameras.index(self.camera) + 1) % len(self.cameras)]

    def pump(self) -> None:
        """Read the window's events: keys and close. Pad events are left for the gamepad."""
        pg = self.pygame
        self.key_events = []
        for event in pg.event.get(eventtype=[pg.QUIT, pg.KEYDOWN, pg.WINDOWCLOSE]):
            if event.type in (pg.QUIT, pg.WINDOWCLOSE):
                self.closed = True
            elif event.type == pg.KEYDOWN:
                self.key_events.append(event.key)
        # Motion and text events would otherwise pile up; the gamepad reads its state directly.
        pg.event.clear(eventtype=[pg.MOUSEMOTION, pg.TEXTINPUT, pg.KEYUP, pg.JOYAXISMOTION, pg.CONTROLLERAXISMOTION,
                                  pg.JOYBUTTONDOWN, pg.JOYBUTTONUP, pg.JOYHATMOTION])

    def show(self, hud: HudState, deadline: float = math.inf) -> None:
        """Read input; draw a frame if it can be done before `deadline` [s, perf_counter], the next
        control tick (software rendering can be slower than the control period: control wins)."""
        pg = self.pygame
        self.pump()
        self.ticks += 1
        start = time.perf_counter()
        estimate = 1.2 * sorted(self._frame_costs)[len(self._frame_costs) // 2]
        if start + estimate > deadline and start - self._last_frame < MAX_FRAME_GAP:
            return
        frame = self.renderer.render(self.env.data, self.camera)
        surface = pg.image.frombuffer(frame.tobytes(), (frame.shape[1], frame.shape[0]), "RGB")
        self.window.blit(surface, (0, 0))
        self._draw_hud(hud)
        pg.display.flip()
        self._last_frame = time.perf_counter()
        if self.frames:  # the first frame compiles shaders: not a measure of the next ones
            self._frame_costs.append(self._last_frame - start)
        self.frames += 1

    def _draw_hud(self, hud: HudState) -> None:
        pg = self.pygame
        target = f"/{hud.target}" if hud.target else ""
        success = ("SUCCESS" if hud.success else "not yet") + \
            (f" (held {hud.held}/{hud.hold_needed})" if hud.success else "")
        lines = [
            f"{hud.env_id}   attempt {hud.attempt}   saved {hud.saved}{target}",
            f"step {hud.step}/{hud.max_steps}   {success}",
            f"gripper {'closed' if hud.gripper_closed else 'open'}   camera {self.camera}"
            + ("   PRECISION" if hud.precision else ""),
        ]
        if hud.status:
            lines.append(hud.status)
        panel = pg.Surface((self.size[0], 22 * len(lines) + 8), pg.SRCALPHA)
        panel.fill((0, 0, 0, 150))
        self.window.blit(panel, (0, 0))
        for i, text in enumerate(lines):
            colour = (120, 255, 120) if (i == 1 and hud.success) else (255, 220, 90) if text == hud.status \
                else (255, 255, 255)
            self.window.blit(self.font.render(text, True, colour), (8, 6 + 22 * i))
        if self.legend:
            legend = pg.Surface((self.size[0], 22 * len(self.legend) + 8), pg.SRCALPHA)
            legend.fill((0, 0, 0, 150))
            top = self.size[1] - legend.get_height()
            self.window.blit(legend, (0, top))
            for i, text in enumerate(self.legend):
                self.window.blit(self.font.render(text, True, (220, 220, 220)), (8, top + 6 + 22 * i))

    def screenshot(self, path: str) -> None:
        self.pygame.image.save(self.window, path)

    def close(self) -> None:
        self.renderer.close()
        self.pygame.display.quit()
