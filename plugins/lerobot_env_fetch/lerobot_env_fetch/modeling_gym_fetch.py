"""A `gym-fetch train` run acting in LeRobot's tools: `lerobot-eval --policy.path=FOLDER` (`export_policy`).

LeRobot hands a policy its batch (`observation.state`, `observation.environment_state`,
`observation.images.<camera>` as floats in [0, 1]); `Inputs.observation` turns it back into the observation
dict our policy acts on, exactly: the env (`--env.type=fetch`) gives the vector our env gives, as float32,
which is what our policy reads it as, and the images as uint8 / 255.
"""

from __future__ import annotations

import builtins
import os
import pathlib
from collections.abc import Mapping
from typing import Any, NamedTuple, TypeVar

import gymnasium as gym
import numpy as np
import torch
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.utils.constants import OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

import fetch
import fetch.learn
from fetch.camera_obs import image_key
from fetch.dataset.exports import lerobot as export
from fetch.errors import FetchError
from fetch.learn.data import unseen_by_pixels
from fetch.learn.runtime import Policy
from lerobot_env_fetch.configuration_gym_fetch import TYPE, GymFetchConfig

T = TypeVar("T", bound="GymFetchPolicy")


class Inputs(NamedTuple):
    """Where LeRobot's observation goes in the observation our policy reads: the vector's length, the
    indices `observation.state` fills (all of it for a state policy, the robot's own readings for a camera
    policy: the rest stays 0, which the policy never sees), the achieved goal's slice, each camera's key."""

    size: int
    state: np.ndarray
    achieved: slice
    cameras: tuple[str, ...]
    instruction: str

    @classmethod
    def of(cls, policy: Policy) -> Inputs:
        """`policy`'s inputs, refused where the env LeRobot makes cannot give what it sees."""
        env: Any = gym.make(policy.env_id).unwrapped
        try:
            layout, achieved, instruction = dict(env.observation_layout), env.task.achieved, env.task.instruction
        finally:
            env.close()
        size = max(part.stop for part in layout.values())
        cameras = tuple(policy.config.cameras)
        state = export.state_index(export.state_layout(layout, cameras))
        if cameras:  # with cameras the env gives the robot's own readings: the policy must see nothing else
            unseen = set(unseen_by_pixels(layout, policy.config.goal_offsets)) - set(policy.config.blind)
            if unseen:
                raise FetchError(f"this camera policy also sees {len(unseen)} values of the state beyond the robot's "
                                 "own readings, which LeRobot's env with cameras does not give")
        return cls(size, state, layout[achieved], cameras, instruction)

    def observation(self, batch: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """Our observation dict, (B, ...) arrays, from LeRobot's batch of (B, ...) tensors."""
        keys = (OBS_STATE, OBS_ENV_STATE, *(f"{OBS_IMAGES}.{c}" for c in self.cameras))
        missing = [k for k in keys if k not in batch]
        if missing:
            raise FetchError(f"the policy reads {', '.join(missing)}, which the env does not give: evaluate it with "
                             f"--env.cameras={','.join(self.cameras) or 'none'}")
        given = _numpy(batch[OBS_STATE]).astype(np.float32)
        if given.shape[1:] != self.state.shape:
            raise FetchError(f"observation.state has {given.shape[1:]} values, the policy reads {len(self.state)}: "
                             f"evaluate it with --env.cameras={','.join(self.cameras) or 'none'} on its task")
        vector = np.zeros((len(given), self.size), np.float32)
        vector[:, self.state] = given
        obs = {"observation": vector, "achieved_goal": vector[:, self.achieved].copy(),
               "desired_goal": _numpy(batch[OBS_ENV_STATE]).astype(np.float32)}
        for camera in self.cameras:  # LeRobot's (B, 3, H, W) in [0, 1], from the env's uint8: exactly back
            image = _numpy(batch[f"{OBS_IMAGES}.{camera}"]).transpose(0, 2, 3, 1)
            obs[image_key(camera)] = np.clip(np.rint(image * 255.0), 0, 255).astype(np.uint8)
        return obs


def _numpy(value: Any) -> np.ndarray:
    return value.detach().cpu().numpy() if isinstance(value, torch.Tensor) else np.asarray(value)


class GymFetchPolicy(PreTrainedPolicy):
    """The policy of a run exported by `export_policy`: acts as `gym-fetch eval` runs it, on the CPU."""

    config_class = GymFetchConfig
    name = TYPE

    def __init__(self, config: GymFetchConfig, **kwargs: Any) -> None:
        super().__init__(config)
        self.run: Policy | None = None
        self.inputs: Inputs | None = None

    @classmethod
    def from_pretrained(cls: builtins.type[T], pretrained_name_or_path: str | os.PathLike[str], *,
                        config: GymFetchConfig | None = None, revision: str | None = None,  # type: ignore[override]
                        **kwargs: Any) -> T:
        """The policy in `pretrained_name_or_path`: a folder `export_policy` wrote, or a Hub repo holding one."""
        folder = pathlib.Path(pretrained_name_or_path)
        if not folder.is_dir():
            from huggingface_hub import snapshot_download

            folder = pathlib.Path(snapshot_download(str(pretrained_name_or_path), revision=revision))
        if config is None:
            config = GymFetchConfig.from_pretrained(folder)
        policy = cls(config)
        policy.load_run(folder)
        return policy

    def load_run(self, folder: pathlib.Path) -> None:
        """Our policy from `folder`'s checkpoint, checked against this config and the env LeRobot can make."""
        run = fetch.learn.load(folder)
        config = self.config
        described = (config.env_id, tuple(config.cameras), config.image_size, config.image_quality)
        actual = (run.env_id, tuple(run.config.cameras), run.config.image_size, run.config.image_quality)
        if described != actual:
            raise FetchError(f"{folder}: config.json describes {described} (task, cameras, image size, quality), its "
                             f"checkpoint holds {actual}")
        self.run, self.inputs = run, Inputs.of(run)

    def reset(self) -> None:
        if self.run is not None:
            self.run.reset()

    @torch.no_grad()
    def select_action(self, batch: dict[str, Any], **kwargs: Any) -> torch.Tensor:
        if self.run is None or self.inputs is None:
            raise FetchError("a gym_fetch policy is made from a folder: --policy.path=FOLDER (export_policy)")
        tasks = batch.get("task")
        if tasks is not None and any(t and t != self.inputs.instruction for t in tasks):
            raise FetchError(f"the policy learnt {self.run.env_id} ({self.inputs.instruction!r}); the env asks "
                             f"{sorted(set(tasks))}: evaluate it with --env.task={self.run.env_id}")
        return torch.from_numpy(self.run(self.inputs.observation(batch)))

    def predict_action_chunk(self, batch: dict[str, Any], **kwargs: Any) -> torch.Tensor:
        return self.select_action(batch)[:, None]

    def forward(self, batch: dict[str, Any]) -> tuple[torch.Tensor, dict | None]:
        raise FetchError("a gym_fetch policy is trained with `gym-fetch train`, not lerobot-train")

    def get_optim_params(self) -> dict:
        raise FetchError("a gym_fetch policy is trained with `gym-fetch train`, not lerobot-train")
