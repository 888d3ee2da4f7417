"""The collection window: the scene from a switchable camera, a heads-up display and the controls legend.

It is a pygame window showing MuJoCo's offscreen rendering, so the same event loop serves the window,
the keyboard and the gamepad. The scene is rendered on a thread of its own: with software GL a frame
costs about a control period, and the control loop must never wait for one. pygame is imported here
only, when a window is asked for.
"""

from __future__ import annotations

import collections
import math
import os
import sys
import threading
import time
from typing import Any

import mujoco
import mujoco.gl_context
import numpy as np

from fetch._environ import environ
from fetch._gl import check_gl, context_class, has_display
from fetch.errors import FetchError
from fetch.rendering import CAMERAS, camera_names
from fetch.teleop.session import HudState

MAX_GEOMS = 2000
"""Per scene; the largest task draws under 100 geoms and sites."""
RENDER_NICE = 10
"""How much lower the render thread's priority is than the control thread's (Linux, where threads have
their own). The GL driver's worker threads, started from it, inherit it: on a busy CPU the picture waits,
the control tick does not."""
START_TIMEOUT = 30.0
"""[s] for the render thread to make its GL context (well under a second normally)."""
STOP_TIMEOUT = 5.0
"""[s] for the render thread to finish its frame and free its GL context."""
def camera_yaw(model: mujoco.MjModel, data: mujoco.MjData, camera: str) -> float:
    """[rad] The rotation from the seed's fixed stick mapping (stick up = world +y) to the camera's:
    stick up then moves the hand away from the viewer, along the camera's view on the table."""
    cam = model.camera(camera).id
    forward = -data.cam_xmat[cam].reshape(3, 3)[:, 2]  # a camera looks along its -z axis
    if math.hypot(forward[0], forward[1]) < 1e-6:  # looking straight down: use its image up
        forward = data.cam_xmat[cam].reshape(3, 3)[:, 1]
    return math.atan2(-forward[0], forward[1])


class FrameThread:
    """Renders scenes into pixels on a thread of its own, which owns the GL context.

    The caller fills `scene` (`mjv_updateScene`, on its own thread, from its own MjData), `post()`s it and
    gets a free one in its place; the thread draws the newest posted scene whenever it is idle, and
    `take()` returns the newest finished frame not yet taken. Three scenes and three pixel buffers rotate
    under one lock, held only for the swaps, so neither side ever waits for the other's work or writes
    what the other reads. A failure in the thread is kept in `error` for the caller to raise.
    """

    def __init__(self, model: mujoco.MjModel, size: tuple[int, int]) -> None:
        width, height = size
        # The offscreen buffer must hold the image; this model is the env's own copy.
        model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
        model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
        self._model = model
        self._size = size
        self._context = context_class()
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self.scene, self._posted, self._drawing = (self._new_scene() for _ in range(3))
        self._back, self._ready, self._front = (np.zeros((height, width, 3), np.uint8) for _ in range(3))
        self._lock = threading.Condition()
        self._new = self._fresh = self._stop = False
        self.error: BaseException | None = None
        self.frames = 0
        """Frames rendered."""
        self._started = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fetch-viewer-render", daemon=True)
        self._thread.start()
        if not self._started.wait(START_TIMEOUT):
            self.close()
            raise FetchError(f"the viewer's OpenGL context was not made within {START_TIMEOUT:.0f} s; "
                             "use --render none")
        if self.error is not None:
            raise FetchError(
                f"the viewer cannot render with MUJOCO_GL={os.environ.get('MUJOCO_GL', '(unset)')}: "
                f"{type(self.error).__name__}: {self.error}; use --render none (headless), or check the "
                "display's OpenGL (glxinfo)") from self.error

    def _new_scene(self) -> mujoco.MjvScene:
        scene = mujoco.MjvScene(self._model, maxgeom=MAX_GEOMS)
        # Reflections and the skybox cost a third of a software-rendered frame (llvmpipe).
        scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
        return scene

    def post(self) -> None:
        """Hand `scene` to the render thread; `scene` is then a free one to fill next time."""
        with self._lock:
            self.scene, self._posted = self._posted, self.scene
            self._new = True
            self._lock.notify()

    def take(self) -> np.ndarray | None:
        """The newest frame not yet taken, (H, W, 3) uint8 with OpenGL's bottom-up rows, or None. It stays
        valid until the next `take`."""
        with self._lock:
            if not self._fresh:
                return None
            self._front, self._ready = self._ready, self._front
            self._fresh = False
            return self._front

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def close(self) -> None:
        """Stop the thread (after its current frame) and wait for it to free the GL context."""
        with self._lock:
            self._stop = True
            self._lock.notify()
        self._thread.join(STOP_TIMEOUT)

    def _run(self) -> None:
        try:
            _lower_priority(RENDER_NICE)
            # Made, used and freed on this thread: a GL context is current on one thread at a time.
            gl = self._context(*self._size)
            try:
                gl.make_current()  # nothing else is current on this thread (as_current is mujoco >= 3.4)
                context = mujoco.MjrContext(self._model, mujoco.mjtFontScale.mjFONTSCALE_100)
                try:
                    mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, context)
                    self._started.set()
                    self._draw_until_stopped(context)
                finally:
                    context.free()
            finally:
                gl.free()
        except BaseException as exc:  # kept for the caller to raise on its own thread
            self.error = exc
        finally:
            self._started.set()

    def _draw_until_stopped(self, context: mujoco.MjrContext) -> None:
        while True:
            with self._lock:
                while not (self._new or self._stop):
                    self._lock.wait()
                if self._stop:
                    return
                self._posted, self._drawing = self._drawing, self._posted
                self._new = False
            # Both calls release the GIL: the control thread runs meanwhile.
            mujoco.mjr_render(self._rect, self._drawing, context)
            mujoco.mjr_readPixels(self._back, None, self._rect, context)
            with self._lock:
                self._back, self._ready = self._ready, self._back
                self._fresh = True
                self.frames += 1


def _lower_priority(nice: int) -> None:
    """Lower the calling thread's priority by `nice` (Linux only: elsewhere it would be the process's)."""
    if sys.platform != "linux":
        return
    tid = threading.get_native_id()
    try:
        os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + nice)
    except OSError:  # a sandbox may forbid it: the picture then competes with control, nothing worse
        pass


class Viewer:
    """A window on the env: `show(hud)` once per tick reads input, hands the scene to the render thread
    and shows its newest frame with the HUD; it never waits for a frame.

    Keys pressed since the last `show` are in `key_events` (pygame key codes), the window's close
    button sets `closed`. Raises FetchError when no window can be opened (no display, no OpenGL).
    """

    def __init__(self, env: Any, legend: tuple[str, ...] = (), size: tuple[int, int] = (640, 480),
                 camera: str = "front") -> None:
        if not has_display() and os.environ.get("SDL_VIDEODRIVER") not in ("dummy", "offscreen"):
            raise FetchError("no display for the viewer window; use --render none (headless), or run under "
                             "a desktop session or `xvfb-run`")
        check_gl()
        self.env = env.unwrapped
        model = self.env.model
        self.cameras = [c for c in CAMERAS if c in camera_names(model)]
        if camera not in self.cameras:
            raise FetchError(f"unknown camera {camera!r}; known: {', '.join(self.cameras)}")
        self.camera = camera
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = model.camera(camera).id
        self._option = mujoco.MjvOption()
        self.size = size
        # The GL context first: with MUJOCO_GL=egl, a context made after SDL opened its X11 window
        # fails (EGL_BAD_ACCESS).
        self._frames = FrameThread(model, size)
        # SDL's own X11 framebuffer: by default SDL draws the window through OpenGL, which with software GL
        # (llvmpipe under Xvfb) took 6-13 ms a flip on the control thread, against about 0.5 ms this way.
        # SDL reads the hint when the window is made: it is set for that only.
        with environ(PYGAME_HIDE_SUPPORT_PROMPT="1", SDL_FRAMEBUFFER_ACCELERATION="0"):
            import pygame

            self.pygame = pygame
            try:
                pygame.display.init()
                pygame.font.init()
                self.window = pygame.display.set_mode(size)
            except pygame.error as e:
                self._frames.close()
                raise FetchError(f"cannot open the viewer window: {e}; use --render none") from e
        pygame.display.set_caption(f"gym-fetch-v2: {self.env.spec.id if self.env.spec else 'collect'}")
        self.font = pygame.font.Font(None, 22)
        self.legend = legend
        self.key_events: list[int] = []
        self.closed = False
        self.frames = 0
        """Frames shown."""
        self.ticks = 0
        self._shown: collections.deque[float] = collections.deque(maxlen=25)

    def yaw(self) -> float:
        return camera_yaw(self.env.model, self.env.data, self.camera)

    def next_camera(self) -> None:
        self.camera = self.cameras[(self.cameras.index(self.camera) + 1) % len(self.cameras)]
        self._camera.fixedcamid = self.env.model.camera(self.camera).id

    @property
    def fps(self) -> float:
        """[1/s] Frames shown per second, over the last second or so: what the render thread manages."""
        shown = self._shown
        return (len(shown) - 1) / (shown[-1] - shown[0]) if len(shown) > 1 and shown[-1] > shown[0] else 0.0

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

    def show(self, hud: HudState) -> None:
        """Read input; post the current scene for rendering; show the newest rendered frame, if a new one
        is ready, under the HUD. Raises FetchError if the render thread failed."""
        pg = self.pygame
        self.pump()
        self.ticks += 1
        if self._frames.error is not None:
            error = self._frames.error
            raise FetchError(f"the viewer's render thread failed: {type(error).__name__}: {error}") from error
        env = self.env
        mujoco.mjv_updateScene(env.model, env.data, self._option, None, self._camera,
                               mujoco.mjtCatBit.mjCAT_ALL, self._frames.scene)
        self._frames.post()
        pixels = self._frames.take()
        if pixels is None:
            return
        surface = pg.image.frombuffer(pixels, self.size, "RGB")
        self.window.blit(pg.transform.flip(surface, False, True), (0, 0))  # GL's rows run bottom-up
        self._draw_hud(hud)
        pg.display.flip()
        self.frames += 1
        self._shown.append(time.perf_counter())

    def _draw_hud(self, hud: HudState) -> None:
        pg = self.pygame
        target = f"/{hud.target}" if hud.target else ""
        success = ("SUCCESS" if hud.success else "not yet") + \
            (f" (held {hud.held}/{hud.hold_needed})" if hud.success else "")
        lines = [
            f"{hud.env_id}   attempt {hud.attempt}   saved {hud.saved}{target}",
            f"step {hud.step}/{hud.max_steps}   {success}",
            f"gripper {'closed' if hud.gripper_closed else 'open'}   camera {self.camera} ({self.fps:.0f} frames/s)"
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
        self._frames.close()
        self.pygame.display.quit()
