"""Images of a dataset's saved states: restore each state in the dataset's env, render a camera.

A demo's `states` hold the full physics state (goal included), so its images can be made at any
time, from any camera, at any size, bit-identical to images rendered while it was recorded.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from fetch.errors import FetchError, UnknownNameError


def camera_names(env_id: str, env_kwargs: dict[str, Any]) -> tuple[str, ...]:
    """The cameras of an env (its model's, in order), without a GL context."""
    import fetch  # noqa: F401  (registers the ids)

    env: Any = gym.make(env_id, **env_kwargs).unwrapped
    try:
        return tuple(env.model.camera(i).name for i in range(env.model.ncam))
    finally:
        env.close()


def check_camera(camera: str, cameras: tuple[str, ...]) -> None:
    if camera not in cameras:
        raise UnknownNameError("camera", camera, cameras)


class StateRenderer:
    """Renders states of one env (id and kwargs, as a dataset records them) offscreen."""

    def __init__(self, env_id: str, env_kwargs: dict[str, Any], width: int, height: int) -> None:
        import fetch  # noqa: F401  (registers the ids; picks an offscreen GL backend)
        from fetch.rendering import OffscreenRenderer

        if width <= 0 or height <= 0:
            raise FetchError(f"image size must be positive pixels, got {width}x{height}")
        env: Any = gym.make(env_id, **env_kwargs).unwrapped
        self.env = env
        model = env.model
        self.cameras = tuple(model.camera(i).name for i in range(model.ncam))
        self.width, self.height = width, height
        # The same renderer and settings as `collect --cameras`: images match those recorded live.
        self._renderer = OffscreenRenderer(model, width, height)

    def check_camera(self, camera: str) -> None:
        check_camera(camera, self.cameras)

    def frame(self, state: np.ndarray, camera: str) -> np.ndarray:
        """The (H, W, 3) uint8 image of one state."""
        self.env.set_state(state)
        return self._renderer.render(self.env.data, camera)

    def frames(self, states: np.ndarray, camera: str) -> np.ndarray:
        """(N, H, W, 3) uint8 images of N states."""
        self.check_camera(camera)
        out = np.empty((len(states), self.height, self.width, 3), np.uint8)
        for i, state in enumerate(states):
            out[i] = self.frame(state, camera)
        return out

    def close(self) -> None:
        self._renderer.close()
        self.env.close()

    def __enter__(self) -> StateRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
