"""The collection window's render thread: MuJoCo scenes into pixels, off the control thread.

With software GL a frame costs one to two control periods, so the window never draws on the thread
that steps the arm: it hands scenes to a thread of its own, which owns the GL context, and shows the
newest finished pixels when there are some (`fetch.teleop.viewer`).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from typing import NamedTuple

import mujoco
import mujoco.gl_context
import numpy as np

from fetch._gl import context_class
from fetch.errors import FetchError

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


class Drawn(NamedTuple):
    """A finished frame: the `tag` its caller posted it with, and what it cost the render thread [s, wall
    clock: on a busy CPU this includes the time the thread waited for one]."""

    tag: int
    seconds: float


class FrameThread:
    """Renders views of scenes into pixels on a thread of its own, which owns the GL context.

    A frame is `VIEWS` views (the main camera, the inset), each a scene and a size [px, (0, 0): not
    drawn]; `shadows` says for each view whether the key light casts them. The caller fills `frame`
    (`mjv_updateScene` into its scenes, on its own thread, from its own MjData, and the sizes),
    `post()`s it and gets a free one in its place; the thread draws the newest posted frame whenever it
    is idle, and `take()` returns the newest finished pixels not yet taken. A frame's `tag` (the caller's
    number for what it shows) comes back with its pixels in `taken`, with the time it took to draw.
    Three frames and three sets of pixel buffers rotate under one lock, held only for the swaps, so
    neither side ever waits for the other's work or writes what the other reads. A failure in the
    thread is kept in `error` for the caller to raise.
    """

    VIEWS = 2

    def __init__(self, model: mujoco.MjModel, max_size: tuple[int, int], shadows: tuple[bool, ...] = (True, False)
                 ) -> None:
        width, height = max_size
        # The offscreen buffer must hold the largest view; this model is the window's own copy.
        model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
        model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
        self._model = model
        self._max = max_size
        self._context = context_class()
        self._shadows = shadows
        self.frame, self._posted, self._drawing = (self._new_frame() for _ in range(3))
        self._back, self._ready, self._front = ([np.zeros((0, 0, 3), np.uint8)] * self.VIEWS for _ in range(3))
        self._lock = threading.Condition()
        self._new = self._fresh = self._stop = False
        self.error: BaseException | None = None
        self.frames = 0
        """Frames rendered."""
        self._drawn = self.taken = Drawn(-1, 0.0)
        """`taken`: the frame whose pixels `take()` last returned."""
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

    def _new_frame(self) -> _Frame:
        return _Frame([self._new_scene(shadows) for shadows in self._shadows])

    def _new_scene(self, shadows: bool) -> mujoco.MjvScene:
        scene = mujoco.MjvScene(self._model, maxgeom=MAX_GEOMS)
        # Reflections cost a third of a software-rendered frame (llvmpipe); the sky and the shadows
        # are what a person judges depth by (docs/window.md has what each costs).
        scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
        return scene

    def post(self) -> None:
        """Hand `frame` to the render thread; `frame` is then a free one to fill next time."""
        with self._lock:
            self.frame, self._posted = self._posted, self.frame
            self._new = True
            self._lock.notify()

    def take(self) -> list[np.ndarray] | None:
        """The newest views not yet taken, each (H, W, 3) uint8 with OpenGL's bottom-up rows (empty where a
        view was not drawn), or None. They stay valid until the next `take`."""
        with self._lock:
            if not self._fresh:
                return None
            self._front, self._ready = self._ready, self._front
            self._fresh = False
            self.taken = self._drawn
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
            gl = self._context(*self._max)
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
            back = self._back
            start = time.perf_counter()
            for i, (scene, (width, height)) in enumerate(zip(self._drawing.scenes, self._drawing.sizes, strict=True)):
                width, height = min(width, self._max[0]), min(height, self._max[1])
                if back[i].shape[:2] != (height, width):
                    back[i] = np.zeros((height, width, 3), np.uint8)
                if width and height:
                    rect = mujoco.MjrRect(0, 0, width, height)
                    # Both calls release the GIL: the control thread runs meanwhile.
                    mujoco.mjr_render(rect, scene, context)
                    mujoco.mjr_readPixels(back[i], None, rect, context)
            drawn = Drawn(self._drawing.tag, time.perf_counter() - start)
            with self._lock:
                self._back, self._ready = self._ready, self._back
                self._drawn = drawn
                self._fresh = True
                self.frames += 1


class _Frame:
    """One frame's views: a scene each and its size [px] (what `FrameThread` draws), and the caller's `tag`."""

    def __init__(self, scenes: list[mujoco.MjvScene]) -> None:
        self.scenes = scenes
        self.sizes = [(0, 0)] * len(scenes)
        self.tag = -1


def _lower_priority(nice: int) -> None:
    """Lower the calling thread's priority by `nice` (Linux only: elsewhere it would be the process's)."""
    if sys.platform != "linux":
        return
    tid = threading.get_native_id()
    try:
        os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + nice)
    except OSError:  # a sandbox may forbid it: the picture then competes with control, nothing worse
        pass
