"""A trained policy as a callable: `policy = load(RUN)`, `policy.reset()`, `action = policy(obs)`."""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from fetch.camera_obs import image_key
from fetch.errors import FetchError
from fetch.learn import checkpoint as ckpt
from fetch.learn.checked import load_weights, one_line
from fetch.learn.data import Normalizer, acted_actions, flat_obs
from fetch.learn.kinds import KINDS, PolicyConfig, kind
from fetch.learn.policies import build, implementation
from fetch.tasks import registered_horizon


class Policy:
    """Acts on one observation dict (action (4,)) or a batch of them (leading axis B: actions (B, 4)).

    `reset()` starts new episodes (all of the batch at once). How it acts from step to step is its
    kind's (`fetch.learn.policies.Kind.actor`).
    """

    def __init__(self, config: PolicyConfig, model: torch.nn.Module, normalizer: Normalizer, env_id: str,
                 env_kwargs: dict[str, Any], seeds: frozenset[int], step: int, horizon: int | None = None) -> None:
        self.config = config
        self.model = model.eval()
        self.normalizer = normalizer
        self.env_id = env_id
        self.env_kwargs = env_kwargs
        self.seeds = seeds
        """The reset seeds of the dataset it learnt from: evaluation uses others."""
        self.trained_steps = step
        self.horizon = horizon if horizon is not None else registered_horizon(env_id)
        """[steps] the episode length this policy is given: its task's registered horizon, or more where
        the demos it learnt from took longer (`fetch.learn.data.needed_horizon`)."""
        self._actor = implementation(config.kind).actor(config, self.model)
        self.image_keys = tuple(image_key(c) for c in config.cameras)
        """The observation keys of the camera images it sees (none: a state policy)."""
        self.reset()

    def act_every(self, steps: int) -> None:
        """From now on predict a chunk every `steps` steps (a chunk kind's `act_steps`, 1 to its `chunk`): to act,
        and judge, a run saved before the default changed as one trained now would. New episodes start."""
        if "act_steps" not in kind(self.config.kind).own:
            raise FetchError(f"a {self.config.kind} policy predicts one action a step; act_steps is for the chunk "
                             f"kinds ({', '.join(k.name for k in KINDS if 'act_steps' in k.own)})")
        self.config = dataclasses.replace(self.config, act_steps=steps)  # checked as a checkpoint's would be
        self._actor = implementation(self.config.kind).actor(self.config, self.model)
        self.reset()

    @property
    def observation_kwargs(self) -> dict[str, Any]:
        """What `gym.make` needs, beyond `env_kwargs`, for the observations this policy acts on: its cameras'
        images at its size and quality (`gym.make(policy.env_id, **policy.env_kwargs, **policy.observation_kwargs)`);
        nothing for a state policy."""
        if not self.config.cameras:
            return {}
        return {"cameras": self.config.cameras, "image_size": self.config.image_size,
                "image_quality": self.config.image_quality}

    def reset(self) -> None:
        self._batch: int | None = None
        self._single = True
        self._actor.reset()

    @property
    def spread(self) -> float | np.ndarray | None:
        """How far apart the predictions the last action was made from lie (`fetch.learn.policies.Actor.spread`):
        [action units] a float for one observation, (B,) for a batch; None where the policy makes one prediction
        (one network acting step by step, or a chunk policy's first step)."""
        spread = self._actor.spread
        if spread is None:
            return None
        return float(spread[0]) if self._single else spread

    def __call__(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        x = self.normalizer(flat_obs(obs, self.config.goal_offsets, self.config.blind))
        single = x.ndim == 1
        x = x[None] if single else x
        if self._batch is None:
            self._batch = len(x)
        elif len(x) != self._batch:
            raise FetchError(f"the policy acted on batches of {self._batch} observations since reset(), now "
                             f"{len(x)}; call reset() when the batch changes")
        images = [torch.from_numpy(self._image(obs, key, single)) for key in self.image_keys]
        self._single = single
        with torch.no_grad():
            action = self._actor(torch.from_numpy(x), *images)
        config = self.config
        action = np.clip(acted_actions(action, config.finger_scale, config.finger_span), -1.0, 1.0).astype(np.float32)
        return action[0] if single else action

    def _image(self, obs: Mapping[str, np.ndarray], key: str, single: bool) -> np.ndarray:
        """The (B, H, W, 3) uint8 images under `key`, checked to be what the policy learnt from."""
        if key not in obs:
            raise FetchError(f"the policy sees {', '.join(self.image_keys)}, which the observation lacks; make its env "
                             f"with gym.make({self.env_id!r}, **policy.env_kwargs, **policy.observation_kwargs)")
        image = np.asarray(obs[key])
        image = image[None] if single else image
        size = self.config.image_size
        if image.dtype != np.uint8 or image.shape[1:] != (size, size, 3):
            raise FetchError(f"{key}: the policy learnt from uint8 ({size}, {size}, 3) images, given {image.dtype} "
                             f"{image.shape[1:]}")
        return image


def load(run: str | os.PathLike[str]) -> Policy:
    """The policy a `gym-fetch train` run holds (its last checkpoint), every field of which `ckpt.read` checks."""
    state = ckpt.read(run)
    file = ckpt.file_of(run)
    config = PolicyConfig.from_dict(dict(state["policy"]))
    model = build(config)
    load_weights(file, model, state["model"])
    source = state["source"]
    seeds = frozenset(int(s) for s in state["seeds"].tolist())
    horizon = state.get("horizon")
    try:
        norm = Normalizer(state["norm"]["mean"].numpy(), state["norm"]["std"].numpy())
        return Policy(config, model, norm, str(source["env_id"]), json.loads(source["env_kwargs"]), seeds,
                      int(state["step"]), None if horizon is None else int(horizon))
    except (RuntimeError, ValueError, TypeError, KeyError) as e:  # what the checks did not foresee: one line still
        raise FetchError(f"{file}: its policy cannot be made from it ({one_line(e)})") from e
