"""Images of a dataset's saved states: restore each state in the dataset's env, render a camera.

A demo's `states` hold the full physics state (goal included), so its images can be made at any
time, from any camera, at any size, bit-identical to images rendered while it was recorded.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import fcntl
import itertools
import multiprocessing
import os
import pathlib
import shutil
import stat
import tempfile
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from fetch._processes import start_worker, stop_pool, workers_deaf_to_ctrl_c
from fetch.errors import FetchError
from fetch.looks import Looks


def check_env_camera(env_id: str, env_kwargs: dict[str, Any], camera: str) -> None:
    """UnknownNameError unless the env has `camera` (checked without a GL context)."""
    import fetch  # noqa: F401  (registers the ids)
    from fetch.rendering import check_camera

    env: Any = gym.make(env_id, **env_kwargs).unwrapped
    try:
        check_camera(env.model, camera)
    finally:
        env.close()


class StateRenderer:
    """Renders states of one env (id and kwargs, as a dataset records them) offscreen, at `quality`
    (`rendering.IMAGE_QUALITIES`: a dataset's images at its layout's, a video for people at "full"), with
    the goal's marker hidden where the kwargs say `hide_goal`, and under the kwargs' `looks="random"` with
    the looks of the demo's reset seed, as that env's own camera images are."""

    def __init__(self, env_id: str, env_kwargs: dict[str, Any], width: int, height: int,
                 quality: str = "full") -> None:
        import fetch  # noqa: F401  (registers the ids; picks an offscreen GL backend)
        from fetch.rendering import OffscreenRenderer, camera_names

        if width <= 0 or height <= 0:
            raise FetchError(f"image size must be positive pixels, got {width}x{height}")
        env: Any = gym.make(env_id, **env_kwargs).unwrapped
        self.env = env
        model = env.model
        self.cameras = camera_names(model)
        self.width, self.height = width, height
        self.hide_goal = bool(env_kwargs.get("hide_goal", False))
        self.random_looks = env.looks_mode == "random"
        # The same renderer and settings as `collect --cameras`: images match those recorded live.
        self._renderer = OffscreenRenderer(model, width, height, quality)

    def check_camera(self, camera: str) -> None:
        from fetch.rendering import check_camera

        check_camera(self.env.model, camera)

    def looks(self, seed: int | None) -> Looks | None:
        """The looks of the episode reset with `seed`: None (as modelled) unless the env draws them."""
        if not self.random_looks:
            return None
        if seed is None:
            raise FetchError("this dataset's env draws its looks from each demo's reset seed (looks='random'), "
                             "and a demo here records none: its images cannot be drawn as they were")
        return Looks.for_seed(self.env.model, seed)

    def frame(self, state: np.ndarray, camera: str, looks: Looks | None = None) -> np.ndarray:
        """The (H, W, 3) uint8 image of one state, drawn with `looks` (`looks(seed)`)."""
        self.env.set_state(state)
        return self._renderer.render(self.env.data, camera, hide_goal=self.hide_goal, looks=looks)

    def frames(self, states: np.ndarray, camera: str, seed: int | None = None) -> np.ndarray:
        """(N, H, W, 3) uint8 images of N states of the episode reset with `seed` (its looks)."""
        self.check_camera(camera)
        looks = self.looks(seed)
        out = np.empty((len(states), self.height, self.width, 3), np.uint8)
        for i, state in enumerate(states):
            out[i] = self.frame(state, camera, looks)
        return out

    def close(self) -> None:
        self._renderer.close()
        self.env.close()

    def __enter__(self) -> StateRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- rendering in worker processes ----------------------------------------------------------------
# Each process has its own GL context and interpreter: rendering there neither holds this process's
# GIL nor needs this thread to own a context (GLFW allows windows on the main thread only).

_process_renderer: list[StateRenderer] = []


def _start_process(env_id: str, env_kwargs: dict[str, Any], size: int, quality: str, nice: int, parent: int) -> None:
    start_worker(parent)
    # Software GL (llvmpipe) starts a thread per core in every process; one thread each keeps
    # parallel workers (and a collector's control loop) from contending, unless the user says otherwise.
    os.environ.setdefault("LP_NUM_THREADS", "1")
    if nice:
        os.nice(nice)
    _process_renderer.append(StateRenderer(env_id, env_kwargs, size, size, quality))


def _render_in_process(path: str, cameras: Sequence[str], seed: int | None) -> dict[str, np.ndarray]:
    """Render the states saved at `path` (removed once read), of the episode reset with `seed`."""
    states = np.load(path)
    os.unlink(path)
    renderer = _process_renderer[0]
    return {camera: renderer.frames(states, camera, seed) for camera in cameras}


DIR_PREFIX = "fetch-render-"
"""A render pool's directory in $TMPDIR is named this and a random part."""
LOCK_NAME = "pool.lock"
"""The file in a pool's directory that the pool holds an flock on for its whole life."""


def _make_dir() -> tuple[pathlib.Path, int]:
    """A new pool directory and the descriptor of its held lock. It is made under a hidden name, locked,
    then renamed to its `DIR_PREFIX` name: no pool ever sees a directory of that name unlocked while
    its maker runs."""
    making = pathlib.Path(tempfile.mkdtemp(prefix=f".{DIR_PREFIX}making-"))
    fd = os.open(making / LOCK_NAME, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX)
    final = pathlib.Path(tempfile.mkdtemp(prefix=DIR_PREFIX))
    os.rename(making, final)  # over the empty directory mkdtemp reserved the name with
    return final, fd


def _remove_stale_dirs() -> None:
    """Remove the directories that render pools of processes no longer running left in $TMPDIR (a
    SIGKILLed process runs no cleanup). A pool's directory is known by the lock its pool holds on the
    file `LOCK_NAME` in it as long as it runs: the lock is the file system's, so a pool in another PID
    namespace (a container) is seen as running too. Only this user's directories (not links) holding
    that file are looked at, and only those whose lock can be taken are removed; whatever else bears
    the prefix (a user's folder, another user's, a garbage name) is left alone."""
    for stale in pathlib.Path(tempfile.gettempdir()).glob(f"{DIR_PREFIX}*"):
        try:
            info = os.lstat(stale)
            if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.geteuid():
                continue
            fd = os.open(stale / LOCK_NAME, os.O_RDWR | os.O_NOFOLLOW)
        except OSError:  # gone meanwhile, no lock file (not a pool's), or not ours to open
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # its pool is running
            os.close(fd)
            continue
        try:
            shutil.rmtree(stale, ignore_errors=True)
        finally:
            os.close(fd)


class RenderPool:
    """`workers` processes that render states to square `size` images at `quality` (`StateRenderer`'s);
    `nice` lowers their priority."""

    def __init__(self, env_id: str, env_kwargs: dict[str, Any], size: int, workers: int = 1, nice: int = 0,
                 quality: str = "full") -> None:
        self._workers, self._initargs = workers, (env_id, env_kwargs, size, quality, nice, os.getpid())
        self._pool = self._start()
        # The states go to the workers as files, and only their paths through the pool's pipe. A
        # demo's states fill that pipe (64 KiB), and on a Python without the fix for CPython gh-94777
        # (Debian 12's 3.11.2 is one) a worker that dies while the pool writes to it deadlocks the
        # pool for good: its shutdown waits for a thread stuck writing to the dead worker.
        _remove_stale_dirs()
        self._dir, self._lock = _make_dir()
        self._jobs = itertools.count()
        self._futures: set[concurrent.futures.Future[dict[str, np.ndarray]]] = set()  # not yet done

    def _start(self) -> concurrent.futures.ProcessPoolExecutor:
        return concurrent.futures.ProcessPoolExecutor(
            self._workers, mp_context=multiprocessing.get_context("spawn"),  # no GL or HDF5 state inherited
            initializer=_start_process, initargs=self._initargs)

    def replace_workers(self) -> None:
        """Start new workers in place of a pool that a dead one broke (its futures stay failed)."""
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = self._start()

    def submit(self, states: np.ndarray, cameras: Sequence[str],
               seed: int | None = None) -> concurrent.futures.Future[dict[str, np.ndarray]]:
        """Images of every state, per camera ((N, size, size, 3) uint8), when the future is done; `seed`: the
        episode's reset seed, which its looks are drawn from where the env draws them."""
        path = self._dir / f"{next(self._jobs)}.npy"
        np.save(path, states)
        with workers_deaf_to_ctrl_c():  # recorded inside: a stop that waited for the submit finds it in flight
            future = self._pool.submit(_render_in_process, str(path), tuple(cameras), seed)
            self._futures.add(future)
        future.add_done_callback(self._futures.discard)
        return future

    def close(self) -> None:
        try:
            stop_pool(self._pool, abandon=any(not f.done() for f in list(self._futures)))
        finally:
            shutil.rmtree(self._dir, ignore_errors=True)
            if self._lock >= 0:  # once: the descriptor's number may be reused after close
                with contextlib.suppress(OSError):
                    os.close(self._lock)
                self._lock = -1

    def __enter__(self) -> RenderPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
