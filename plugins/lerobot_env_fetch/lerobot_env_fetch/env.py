"""A gym-fetch-v2 env with LeRobot's observation keys, registered as `lerobot_env_fetch/<env id>`.

LeRobot's `preprocess_observation` renames `agent_pos` to `observation.state`, `environment_state` to
`observation.environment_state` and `pixels/<camera>` to `observation.images.<camera>`. The values are
those `gym-fetch export --to lerobot` writes for the same cameras (`fetch.dataset.exports.lerobot`): the state is
the whole observation vector without cameras, the robot's own readings with them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

import fetch
from fetch.camera_obs import DEFAULT_IMAGE_SIZE, image_key
from fetch.dataset.exports import lerobot as export
from fetch.env import FetchEnv

NAMESPACE = "lerobot_env_fetch"


def gym_id(env_id: str) -> str:
    """The gym id of `env_id` (one of `fetch.ENV_IDS`) with LeRobot's observations."""
    return f"{NAMESPACE}/{env_id}"


class LeRobotFetch(gym.Wrapper):
    """`env`'s observations as LeRobot's keys (float32 vectors, uint8 (H, W, 3) images), `info["is_success"]`
    a bool on every step, the episode ended on success where `terminate_on_success`. `task` is the env id,
    `task_description` the task's instruction (what LeRobot's language-conditioned policies read)."""

    def __init__(self, env: FetchEnv, env_id: str, cameras: Sequence[str], terminate_on_success: bool) -> None:
        super().__init__(env)
        self.cameras = tuple(cameras)
        self.terminate_on_success = terminate_on_success
        self.task = env_id
        self.task_description: str = env.task.instruction
        self._state = export.state_index(export.state_layout(env.observation_layout, self.cameras))
        goal = env.observation_space["desired_goal"].shape
        images = {c: env.observation_space[image_key(c)] for c in self.cameras}
        self.shapes: dict[str, tuple[int, ...]] = {
            "agent_pos": (len(self._state),), "environment_state": goal,
            **{f"pixels/{c}": space.shape for c, space in images.items()}}
        """Each observation's shape, keyed as LeRobot's `EnvConfig.features` (nested keys joined by '/')."""
        spaces: dict[str, gym.Space[Any]] = {
            "agent_pos": gym.spaces.Box(-np.inf, np.inf, self.shapes["agent_pos"], np.float32),
            "environment_state": gym.spaces.Box(-np.inf, np.inf, goal, np.float32),
        }
        if self.cameras:
            spaces["pixels"] = gym.spaces.Dict(images)
        self.observation_space = gym.spaces.Dict(spaces)

    def _observation(self, obs: dict[str, np.ndarray]) -> dict[str, Any]:
        out: dict[str, Any] = {"agent_pos": obs["observation"][self._state].astype(np.float32),
                               "environment_state": obs["desired_goal"].astype(np.float32)}
        if self.cameras:
            out["pixels"] = {c: obs[image_key(c)] for c in self.cameras}
        return out

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, Any], dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        info["is_success"] = bool(info["is_success"])
        return self._observation(obs), info

    def step(self, action: np.ndarray) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["is_success"] = success = bool(info["is_success"])
        return (self._observation(obs), float(reward), bool(terminated or (success and self.terminate_on_success)),
                bool(truncated), info)


def make(env_id: str, cameras: Sequence[str] = (), image_size: int = DEFAULT_IMAGE_SIZE, hide_goal: bool = False,
         terminate_on_success: bool = True, render_mode: str | None = None, width: int = 480,
         height: int = 480, image_quality: str = export.IMAGE_QUALITY) -> LeRobotFetch:
    """`env_id` with LeRobot's observations: `cameras`' `image_size` x `image_size` [px] images drawn at
    `image_quality` (default: as the export draws them), `hide_goal` as the demos were recorded,
    `render_mode`, `width` x `height` [px] for `render()` (LeRobot's videos)."""
    env = FetchEnv(**gym.spec(env_id).kwargs, cameras=tuple(cameras), image_size=image_size, hide_goal=hide_goal,
                   image_quality=image_quality, render_mode=render_mode, width=width, height=height)
    return LeRobotFetch(env, env_id, cameras, terminate_on_success)


def register() -> None:
    """Register `gym_id(env_id)` for each of `fetch.ENV_IDS`, with the same episode length."""
    for env_id in fetch.ENV_IDS:
        if gym_id(env_id) not in gym.registry:
            gym.register(id=gym_id(env_id), entry_point=f"{__name__}:make", kwargs={"env_id": env_id},
                         max_episode_steps=gym.spec(env_id).max_episode_steps, disable_env_checker=True)
