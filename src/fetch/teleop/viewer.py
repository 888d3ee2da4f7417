"""The collection window: the scene from a switchable camera with the wrist camera inset, a heads-up
display and the controls legend; resizable, F11 for full screen.

It is a pygame window showing MuJoCo's offscreen rendering, so the same event loop serves the window,
the keyboard and the gamepad. What it draws is the window's own copy of the scene, with depth cues a
person needs (`fetch.teleop.scenery`). The scene is rendered on a thread of its own: with software GL a
frame costs one to two control periods, and the control loop must never wait for one. pygame is
imported here only, when a window is asked for.
"""

from __future__ import annotations

import collections
import os
import statistics
import time
from typing import Any

import mujoco

from fetch._environ import environ
from fetch._gl import check_gl, has_display
from fetch.errors import FetchError
from fetch.teleop.frames import Drawn, FrameThread
from fetch.teleop.scenery import Scenery, camera_yaw
from fetch.teleop.session import HudState

__all__ = ["FrameThread", "Viewer", "camera_yaw", "window_possible"]

SIZE = (640, 480)
"""[px] the window's size when it opens."""
INSET = (0.28, 160)
"""The wrist camera's inset: this fraction of the window's width, and at least this many pixels (4:3)."""
MARGIN, LINE = 8, 22
"""[px] the HUD's and legend's margin and line height."""
FRAME_BUDGET = 0.036
"""[s] the render time a frame should stay under: a frame posted at one 25 Hz tick is shown at the next only
if it is ready within the period (40 ms), less the tick's own work. Over it, the window draws less
(`Viewer`; what that buys: docs/results/bench_window.md)."""
JUDGED = 12
"""Frames shown whose median render time is held against `FRAME_BUDGET` (half a second at 25 frames/s)."""
ECONOMIES = ("shadows", "inset")
"""What the window stops drawing when frames are over budget, in this order: shadows cost most of a software
GL frame, the inset less."""


def window_possible() -> bool:
    """Whether a window can open: a display, or SDL's windowless drivers (dummy, offscreen: tests)."""
    return has_display() or os.environ.get("SDL_VIDEODRIVER") in ("dummy", "offscreen")


class Viewer:
    """A window on the env: `show(hud)` once per tick reads input, hands the scene to the render thread
    and shows its newest frame with the HUD; it never waits for a frame.

    It opens on the task's view (`fetch.tasks.Task.view`) with the wrist camera inset (the default view
    when the main one is the wrist's); `next_camera` cycles the main one. The window resizes, and F11
    toggles full screen; the HUD and the legend wrap to its width. Keys pressed since the last `show` are
    in `key_events` (pygame key codes), the window's close button sets `closed`. Raises FetchError when
    no window can be opened (no display, no OpenGL).

    What it draws follows from measured frame times, so that a person can steer on software GL or a busy
    CPU: while the median render time of `JUDGED` frames shown is over `frame_budget` [s], it stops drawing
    the next of `ECONOMIES` (shadows, then the inset), judging anew on frames drawn since, and the HUD says
    what it dropped and the frame time that made it ("shadows off: frame 52 ms"). It never draws more again
    in the session: a picture that changes back and forth is worse than a plainer one. `frame_budget=None`
    draws what it was asked to throughout.
    """

    def __init__(self, env: Any, legend: tuple[str, ...] = (), size: tuple[int, int] = SIZE,
                 camera: str | None = None, inset: str | None = "wrist", shadows: bool = True,
                 frame_budget: float | None = FRAME_BUDGET) -> None:
        if not window_possible():
            raise FetchError("no display for the viewer window; use --render none (headless), or run under "
                             "a desktop session or `xvfb-run`")
        check_gl()
        self.env = env.unwrapped
        self.scenery = Scenery(self.env)
        self.cameras = self.scenery.cameras
        self.home = camera or self.env.task.view
        for name in (self.home, inset):
            if name is not None and name not in self.cameras:
                raise FetchError(f"unknown camera {name!r}; known: {', '.join(self.cameras)}")
        self.camera = self.home
        self.inset = inset
        self.shadows = shadows
        """Whether the main view casts shadows now."""
        self.inset_on = inset is not None
        """Whether the inset is drawn now."""
        self.frame_budget = frame_budget
        self.economy = ""
        """What was dropped to keep within `frame_budget`, and the frame time that made it (the HUD's line)."""
        self._dropped: list[tuple[str, float]] = []
        self._judged: list[float] = []
        self._judge_from = 0
        self._views = [mujoco.MjvCamera(), mujoco.MjvCamera()]
        for view in self._views:
            view.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._option = mujoco.MjvOption()
        self.legend = legend
        self.key_events: list[int] = []
        self.closed = False
        self.fullscreen = False
        self.frames = 0
        """Frames shown."""
        self.ticks = 0
        """`show` calls: each posts the scene as it is then, tagged with this count."""
        self.shown_frame = Drawn(-1, 0.0)
        """The newest frame shown: the tick whose scene it drew (`ticks` then) and its render time [s]."""
        self._shown: collections.deque[float] = collections.deque(maxlen=25)
        self.layout: dict[str, tuple[int, int, int, int]] = {}
        """Where the last frame drew each part, (left, top, width, height) [px]: "scene", "inset", "hud",
        "legend"."""
        with environ(PYGAME_HIDE_SUPPORT_PROMPT="1"):
            import pygame
        self.pygame = pygame
        try:
            pygame.display.init()
            pygame.font.init()
            # The offscreen buffer is made once, as large as the desktop: the window may go full screen.
            desktop = pygame.display.get_desktop_sizes() or [size]
        except pygame.error as e:
            raise FetchError(f"cannot open the viewer window: {e}; use --render none") from e
        self._windowed = size
        largest = (max(w for w, _ in desktop), max(h for _, h in desktop))
        # The GL context before the window: with MUJOCO_GL=egl, a context made after SDL opened its X11
        # window fails (EGL_BAD_ACCESS).
        # Shadows in the main view only: a shadow pass costs a software renderer about as much as the view
        # itself, and the inset has the drop line and spot.
        self._frames = FrameThread(self.scenery.model, (max(largest[0], size[0]), max(largest[1], size[1])),
                                   shadows=(shadows, False))
        try:
            self._window = pygame.Window(f"gym-fetch-v2: {self.env.spec.id if self.env.spec else 'collect'}",
                                         size, resizable=True)
            self.window.fill((0, 0, 0))
        except pygame.error as e:
            self._frames.close()
            raise FetchError(f"cannot open the viewer window: {e}; use --render none") from e
        self.font = pygame.font.Font(None, LINE)

    @property
    def window(self) -> Any:
        """The window's surface now (a new one after a resize): what a frame is drawn on."""
        # SDL's own X11 framebuffer: by default SDL draws the window through OpenGL, which with software GL
        # (llvmpipe under Xvfb) took 6-13 ms a flip on the control thread, against about 0.5 ms this way.
        # SDL reads the hint when it makes the window's framebuffer (at first, and after a resize).
        with environ(SDL_FRAMEBUFFER_ACCELERATION="0"):
            return self._window.get_surface()

    @property
    def size(self) -> tuple[int, int]:
        """[px] the window's size now."""
        width, height = self._window.size
        return int(width), int(height)

    def toggle_fullscreen(self) -> None:
        """Full screen, or back to the window's last size (F11)."""
        if self.fullscreen:
            self._window.set_windowed()
            self._window.size = self._windowed
        else:
            self._windowed = self.size
            self._window.set_fullscreen(desktop=True)
        self.fullscreen = not self.fullscreen

    def yaw(self) -> float:
        """[rad] the main camera's heading: a pad's or keyboard's "up" moves the hand away from it."""
        return self.scenery.yaw(self.camera)

    def next_camera(self) -> None:
        self.camera = self.cameras[(self.cameras.index(self.camera) + 1) % len(self.cameras)]

    @property
    def fps(self) -> float:
        """[1/s] Frames shown per second, over the last second or so: what the render thread manages."""
        shown = self._shown
        return (len(shown) - 1) / (shown[-1] - shown[0]) if len(shown) > 1 and shown[-1] > shown[0] else 0.0

    def pump(self) -> None:
        """Read the window's events: keys, F11, close. Pad events are left for the gamepad."""
        pg = self.pygame
        self.key_events = []
        for event in pg.event.get(eventtype=[pg.QUIT, pg.KEYDOWN, pg.WINDOWCLOSE]):
            if event.type in (pg.QUIT, pg.WINDOWCLOSE):
                self.closed = True
            elif event.type == pg.KEYDOWN:
                if event.key == pg.K_F11:
                    self.toggle_fullscreen()
                self.key_events.append(event.key)
        # Motion and text events would otherwise pile up; the gamepad reads its state directly.
        pg.event.clear(eventtype=[pg.MOUSEMOTION, pg.TEXTINPUT, pg.KEYUP, pg.JOYAXISMOTION, pg.CONTROLLERAXISMOTION,
                                  pg.JOYBUTTONDOWN, pg.JOYBUTTONUP, pg.JOYHATMOTION, pg.VIDEORESIZE,
                                  pg.WINDOWRESIZED, pg.WINDOWSIZECHANGED])

    def _inset_size(self, size: tuple[int, int]) -> tuple[int, int]:
        fraction, least = INSET
        width = min(max(int(size[0] * fraction), least), size[0] // 2)
        return width, width * 3 // 4

    def show(self, hud: HudState) -> None:
        """Read input; post the current scene for rendering; show the newest rendered frame, if a new one
        is ready, under the HUD. Raises FetchError if the render thread failed."""
        pg = self.pygame
        self.pump()
        self.ticks += 1
        if self._frames.error is not None:
            error = self._frames.error
            raise FetchError(f"the viewer's render thread failed: {type(error).__name__}: {error}") from error
        scenery = self.scenery
        scenery.sync(self.env.data)
        size = self.size
        frame = self._frames.frame
        inset = (self.home if self.camera == self.inset else self.inset) if self.inset_on else None
        frame.scenes[0].flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self.shadows
        for i, (camera, view_size) in enumerate(((self.camera, size), (inset, self._inset_size(size)))):
            frame.sizes[i] = view_size if camera is not None else (0, 0)
            if camera is None:
                continue
            self._views[i].fixedcamid = scenery.model.camera(camera).id
            mujoco.mjv_updateScene(scenery.model, scenery.data, self._option, None, self._views[i],
                                   mujoco.mjtCatBit.mjCAT_ALL, frame.scenes[i])
            scenery.mark(frame.scenes[i])
        frame.tag = self.ticks
        self._frames.post()
        views = self._frames.take()
        if views is None:
            return
        main, small = views
        window = self.window
        if main.shape[:2] != (size[1], size[0]) or window.get_size() != size:  # a resize: the next one fits
            return
        window.blit(pg.transform.flip(pg.image.frombuffer(main, size, "RGB"), False, True), (0, 0))
        self.layout = {"scene": (0, 0, *size)}
        if small.size:
            h, w, _ = small.shape
            left, top = size[0] - w - MARGIN, MARGIN
            pg.draw.rect(window, (255, 255, 255), (left - 2, top - 2, w + 4, h + 4))
            window.blit(pg.transform.flip(pg.image.frombuffer(small, (w, h), "RGB"), False, True), (left, top))
            self.layout["inset"] = (left, top, w, h)
        self._draw_hud(window, hud, size)
        self._window.flip()
        self.shown_frame = self._frames.taken
        self.frames += 1
        self._shown.append(time.perf_counter())
        self._judge(self.shown_frame)

    def _judge(self, drawn: Drawn) -> None:
        """Count a shown frame's render time; after `JUDGED` of them drawn as the window draws now, drop the
        next economy if their median is over the budget."""
        left = [name for name in ECONOMIES if (self.shadows if name == "shadows" else self.inset_on)]
        if self.frame_budget is None or not left or drawn.tag < self._judge_from:
            return
        self._judged.append(drawn.seconds)
        if len(self._judged) < JUDGED:
            return
        median = statistics.median(self._judged)
        self._judged = []
        if median <= self.frame_budget:
            return
        if left[0] == "shadows":
            self.shadows = False
        else:
            self.inset_on = False
        self._dropped.append((left[0], median))
        self.economy = ", ".join(f"{name} off: frame {1e3 * seconds:.0f} ms" for name, seconds in self._dropped)
        self._judge_from = self.ticks + 1  # frames posted from the next tick on are drawn without it

    def _hud_groups(self, hud: HudState) -> list[tuple[list[str], tuple[int, int, int]]]:
        """The HUD's lines, each a list of items to wrap, with its colour."""
        white, green, amber = (255, 255, 255), (120, 255, 120), (255, 220, 90)
        target = f"/{hud.target}" if hud.target else ""
        clock = (["waiting for your first move: the clock starts then"] if hud.waiting else
                 [f"{hud.seconds_left:.1f} s left", f"step {hud.step}/{hud.max_steps}"])
        success = ["SUCCESS" + (f" (held {hud.held}/{hud.hold_needed})" if hud.held else "")] if hud.success else []
        height = self.scenery.height
        state = [f"gripper {'closed' if hud.gripper_closed else 'open'}"]
        state += [f"{100 * height:.1f} cm over the surface below"] if height is not None else []
        view = [f"camera {self.camera}", f"{self.fps:.0f} frames/s"] + (["PRECISION"] if hud.precision else [])
        groups = [([hud.env_id, f"attempt {hud.attempt}", f"saved {hud.saved}{target}"], white),
                  (clock + success, green if hud.success else amber if hud.waiting else white),
                  (state, white), (view, white)]
        if hud.rewound:
            groups.append(([f"rewound {hud.rewound * hud.dt:.0f} s this attempt"], white))
        if self.economy:
            groups.append(([self.economy], amber))
        if hud.status:
            groups.append(([hud.status], amber))
        return groups

    def _draw_hud(self, window: Any, hud: HudState, size: tuple[int, int]) -> None:
        inset = self.layout.get("inset")
        room = (inset[0] if inset else size[0]) - 3 * MARGIN  # the HUD stays left of the inset
        lines = [(line, colour) for items, colour in self._hud_groups(hud) for line in self.wrap(items, room)]
        self.layout["hud"] = self._panel(window, [line for line, _ in lines], [c for _, c in lines], 0, size)
        if self.legend:
            legend = self.wrap(self.legend, size[0] - 2 * MARGIN)
            top = size[1] - LINE * len(legend) - MARGIN
            self.layout["legend"] = self._panel(window, legend, [(220, 220, 220)] * len(legend), top, size)

    def _panel(self, window: Any, lines: list[str], colours: list[tuple[int, int, int]], top: int,
               size: tuple[int, int]) -> tuple[int, int, int, int]:
        """Draw `lines` on a translucent panel at `top`, as wide as its longest line; returns its rectangle."""
        pg = self.pygame
        width = min(max((self.font.size(line)[0] for line in lines), default=0) + 2 * MARGIN, size[0])
        height = LINE * len(lines) + MARGIN
        panel = pg.Surface((width, height), pg.SRCALPHA)
        panel.fill((0, 0, 0, 150))
        window.blit(panel, (0, top))
        for i, (line, colour) in enumerate(zip(lines, colours, strict=True)):
            window.blit(self.font.render(line, True, colour), (MARGIN, top + MARGIN // 2 + LINE * i))
        return 0, top, width, height

    def wrap(self, items: tuple[str, ...] | list[str], width: int) -> list[str]:
        """`items` joined into lines no wider than `width` [px] in the HUD's font (an item wider than that
        alone is cut to fit, with "...")."""
        lines: list[str] = []
        for item in items:
            while self.font.size(item)[0] > width and len(item) > 4:
                item = item[:-4] + "..."
            joined = f"{lines[-1]}   {item}" if lines else item
            if lines and self.font.size(joined)[0] <= width:
                lines[-1] = joined
            else:
                lines.append(item)
        return lines

    def screenshot(self, path: str) -> None:
        self.pygame.image.save(self.window, path)

    def close(self) -> None:
        self._frames.close()
        self._window.destroy()
        self.pygame.display.quit()
