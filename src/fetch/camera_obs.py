"""Camera images in an env's observation dict: one uint8 (H, W, 3) image per camera, made on demand."""

from __future__ import annotations

import concurrent.futures
from collections.abc import Callable, Sequence

import gymnasium as gym
import mujoco
import numpy as np

from fetch import rendering
from fetch.errors import FetchError
from fetch.looks import Looks

DEFAULT_IMAGE_SIZE = 64
"""[px] the side of an observation image when `image_size` is not given, and of the images `collect`, `generate`
and `render-obs` record unless told: 64 x 64 (Dreamer's). The pixel policy's training step is 1.5-1.7x as fast
on it as on robomimic's and DrQ's 84 x 84 (docs/results/pixel_step.md), with the same success on the seven
camera missions (docs/results/mission.md); 84 stays a flag away (`image_size=84`, `--image-size 84`)."""


def image_key(camera: str) -> str:
    """The observation key of a camera's image: the dataset's key for it too (`dataset.schema.image_key`)."""
    return f"{camera}_image"


def check_cameras(model: mujoco.MjModel, cameras: Sequence[str] | None, image_size: int) -> tuple[str, ...]:
    """The cameras as a tuple, after the checks `collect --cameras` makes: each one of the model's, named
    once, and a size from 1 to `rendering.MAX_IMAGE_SIZE` [px] (checked with no cameras too). FetchError
    (one line) otherwise."""
    if isinstance(image_size, bool):  # an int to Python, never a size
        raise FetchError(f"image_size must be a whole number of pixels, got {image_size!r}")
    rendering.check_image_size(int(image_size) if isinstance(image_size, np.integer) else image_size, "image_size")
    if isinstance(cameras, str):
        raise FetchError(f"cameras must be a sequence of camera names, e.g. cameras=({cameras!r},), not the string "
                         f"{cameras!r}")
    names = tuple(cameras or ())
    for camera in names:
        rendering.check_camera(model, camera)
    rendering.check_camera_list(names, "cameras")
    return names


class CameraImages:
    """Renders `cameras` of one model at `size` x `size` [px] for the observation dict, as the dataset's
    images are rendered (`dataset.render.frames.StateRenderer`: the same renderer, settings, size and `quality`,
    `rendering.IMAGE_QUALITIES`), so an image here equals the one `collect --cameras` or `render-obs` records
    for the same state. The GL renderer is made on first use and released by `close`."""

    def __init__(self, model: mujoco.MjModel, cameras: tuple[str, ...], size: int, hide_goal: bool,
                 quality: str = rendering.DEFAULT_IMAGE_QUALITY) -> None:
        self.model, self.cameras, self.size, self.hide_goal = model, cameras, size, hide_goal
        self.quality = rendering.check_image_quality(quality, "image_quality")
        self.keys = tuple(image_key(c) for c in cameras)
        self.renderer: rendering.OffscreenRenderer | None = None
        self._helper_pool: list[_Helper] = []

    def spaces(self) -> dict[str, gym.spaces.Box]:
        """One Box(0, 255, (size, size, 3), uint8) per camera, under its key."""
        shape = (self.size, self.size, 3)
        return {key: gym.spaces.Box(0, 255, shape, np.uint8) for key in self.keys}

    def render(self, data: mujoco.MjData, looks: Looks | None = None) -> dict[str, np.ndarray]:
        """Each camera's image of `data` as it is now (its kinematics current), a fresh array each, drawn
        with `looks` where given."""
        if self.renderer is None:
            self.renderer = rendering.OffscreenRenderer(self.model, self.size, self.size, self.quality)
        renderer = self.renderer
        return {key: renderer.render(data, camera, hide_goal=self.hide_goal, looks=looks)
                for key, camera in zip(self.keys, self.cameras, strict=True)}

    def render_states(self, states: np.ndarray, restore: Callable[[np.ndarray], None], data: mujoco.MjData,
                      spec: int | None = None, threads: int = 1,
                      looks: Sequence[Looks | None] | None = None) -> dict[str, np.ndarray]:
        """(N, size, size, 3) images per camera of N states, each put into `data` by `restore(state)`, the last
        one last. With `threads` > 1 (and `spec`, the `mjtState` the states were saved with), the
        first states are shared out to up to `threads - 1` helper threads, each rendering into its own MjData
        with its own GL context: MuJoCo lets go of Python's lock while it draws, so on a software renderer
        two threads draw 1.6x the frames of one (Bin-place, 84 x 84, 2 cores). The images are the same.
        `looks`: each state's (`fetch.looks`; None, or a None in it: as modelled)."""
        each: list[Looks | None] = list(looks) if looks is not None else [None] * len(states)
        if len(each) != len(states):
            raise ValueError(f"{len(states)} states but {len(each)} looks")
        out = {key: np.empty((len(states), self.size, self.size, 3), np.uint8) for key in self.keys}
        if self.renderer is None:  # made before the helpers' (a renderer's making sets the model's buffer size)
            self.renderer = rendering.OffscreenRenderer(self.model, self.size, self.size, self.quality)
        shared = min(threads, len(states) // HELPER_MIN_STATES + 1) - 1 if spec is not None else 0
        parts = np.array_split(np.arange(len(states)), shared + 1)
        pending = [helper.render(states, index, spec, out, each)
                   for helper, index in zip(self._helpers(shared), parts[:-1], strict=True) if spec is not None]
        for i in parts[-1]:
            restore(states[i])
            for key, image in self.render(data, each[i]).items():
                out[key][i] = image
        for done in pending:
            done.result()
        return out

    def _helpers(self, count: int) -> list[_Helper]:
        while len(self._helper_pool) < count:
            self._helper_pool.append(_Helper(self))
        return self._helper_pool[:max(count, 0)]

    def close(self) -> None:
        """Release the GL renderers (if any were made); closing again does nothing."""
        for helper in self._helper_pool:
            helper.close()
        self._helper_pool = []
        if self.renderer is not None:
            self.renderer.close()
            self.renderer = None


HELPER_MIN_STATES = 4
"""`render_states` hands a helper thread no fewer states than this (a batch of a few renders in the caller)."""


class _Helper:
    """A thread of `CameraImages.render_states` with its own MjData and renderer, made, used and released on
    that thread (a GL context is current on one thread)."""

    def __init__(self, images: CameraImages) -> None:
        self.images = images
        self.thread = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="fetch-render")
        self.data = mujoco.MjData(images.model)
        self.renderer: rendering.OffscreenRenderer | None = None
        self.thread.submit(self._start).result()  # one at a time: making a renderer changes the model's settings

    def _start(self) -> None:
        i = self.images
        self.renderer = rendering.OffscreenRenderer(i.model, i.size, i.size, i.quality)

    def render(self, states: np.ndarray, index: np.ndarray, spec: int, out: dict[str, np.ndarray],
               looks: list[Looks | None]) -> concurrent.futures.Future[None]:
        return self.thread.submit(self._render, states, index, spec, out, looks)

    def _render(self, states: np.ndarray, index: np.ndarray, spec: int, out: dict[str, np.ndarray],
                looks: list[Looks | None]) -> None:
        assert self.renderer is not None
        i = self.images
        for row in index:  # the state and its kinematics, in this thread's own MjData
            mujoco.mj_setState(i.model, self.data, np.asarray(states[row], np.float64), spec)
            mujoco.mj_forward(i.model, self.data)
            for key, camera in zip(i.keys, i.cameras, strict=True):
                out[key][row] = self.renderer.render(self.data, camera, hide_goal=i.hide_goal, looks=looks[row])

    def close(self) -> None:
        def stop() -> None:
            if self.renderer is not None:
                self.renderer.close()
                self.renderer = None

        self.thread.submit(stop).result()
        self.thread.shutdown()
