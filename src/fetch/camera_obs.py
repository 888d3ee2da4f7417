"""Camera images in an env's observation dict: one uint8 (H, W, 3) image per camera, made on demand."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import gymnasium as gym
import mujoco
import numpy as np

from fetch import rendering
from fetch.errors import FetchError

DEFAULT_IMAGE_SIZE = 84
"""[px] the side of an observation image when `image_size` is not given (robomimic's and DrQ's 84 x 84)."""


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
    images are rendered (`dataset.frames.StateRenderer`: the same renderer, settings, size and `quality`,
    `rendering.IMAGE_QUALITIES`), so an image here equals the one `collect --cameras` or `render-obs` records
    for the same state. The GL renderer is made on first use and released by `close`."""

    def __init__(self, model: mujoco.MjModel, cameras: tuple[str, ...], size: int, hide_goal: bool,
                 quality: str = rendering.DEFAULT_IMAGE_QUALITY) -> None:
        self.model, self.cameras, self.size, self.hide_goal = model, cameras, size, hide_goal
        self.quality = rendering.check_image_quality(quality, "image_quality")
        self.keys = tuple(image_key(c) for c in cameras)
        self.renderer: rendering.OffscreenRenderer | None = None

    def spaces(self) -> dict[str, gym.spaces.Box]:
        """One Box(0, 255, (size, size, 3), uint8) per camera, under its key."""
        shape = (self.size, self.size, 3)
        return {key: gym.spaces.Box(0, 255, shape, np.uint8) for key in self.keys}

    def render(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        """Each camera's image of `data` as it is now (its kinematics current), a fresh array each."""
        if self.renderer is None:
            self.renderer = rendering.OffscreenRenderer(self.model, self.size, self.size, self.quality)
        renderer = self.renderer
        return {key: renderer.render(data, camera, hide_goal=self.hide_goal)
                for key, camera in zip(self.keys, self.cameras, strict=True)}

    def render_states(self, states: np.ndarray, restore: Callable[[np.ndarray], None],
                      data: mujoco.MjData) -> dict[str, np.ndarray]:
        """(N, size, size, 3) images per camera of N states, each put into `data` by `restore(state)`."""
        out = {key: np.empty((len(states), self.size, self.size, 3), np.uint8) for key in self.keys}
        for i, state in enumerate(states):
            restore(state)
            for key, image in self.render(data).items():
                out[key][i] = image
        return out

    def close(self) -> None:
        """Release the GL renderer (if one was made); closing again does nothing."""
        if self.renderer is not None:
            self.renderer.close()
            self.renderer = None
