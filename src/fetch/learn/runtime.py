"""A trained policy as a callable: `policy = load(RUN)`, `policy.reset()`, `action = policy(obs)`."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from typing import Any, cast

import numpy as np
import torch

from fetch.errors import FetchError
from fetch.learn import checkpoint as ckpt
from fetch.learn.data import Normalizer, flat_obs
from fetch.learn.policies import Members, PolicyConfig, RecurrentPolicy, build
from fetch.tasks import registered_horizon


class Policy:
    """Acts on one observation dict (action (4,)) or a batch of them (leading axis B: actions (B, 4)).

    `reset()` starts new episodes (all of the batch at once). mlp-chunk predicts a chunk of actions at
    every step and acts on the weighted mean of every chunk's prediction for this step (ACT's
    temporal ensembling); gru carries its hidden state, restarted every `seq_len` steps as in training.
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
        self.reset()

    def reset(self) -> None:
        self._t = 0
        self._batch: int | None = None
        self._chunks: list[np.ndarray] = []  # newest last, each (B, chunk, 4)
        self._hidden: Any = None  # gru: its hidden state (an ensemble's: one per member)

    def __call__(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        x = self.normalizer(flat_obs(obs, self.config.goal_offsets, self.config.blind))
        single = x.ndim == 1
        x = x[None] if single else x
        if self._batch is None:
            self._batch = len(x)
        elif len(x) != self._batch:
            raise FetchError(f"the policy acted on batches of {self._batch} observations since reset(), now "
                             f"{len(x)}; call reset() when the batch changes")
        with torch.no_grad():
            action = self._act(torch.from_numpy(x))
        self._t += 1
        action = np.clip(action, -1.0, 1.0).astype(np.float32)
        return action[0] if single else action

    def _act(self, x: torch.Tensor) -> np.ndarray:
        if self.config.kind == "gru":
            if self._t % self.config.seq_len == 0:
                self._hidden = None
            recurrent = cast(RecurrentPolicy | Members, self.model)
            out, self._hidden = recurrent.step(x[:, None, :], self._hidden)
            return self._mean(out)[:, 0].numpy()
        self._chunks = (self._chunks + [self._mean(self.model(x)).numpy()])[-self.config.chunk:]
        # The chunk made j steps ago predicted this step as its element j; the oldest weighs most.
        ages = range(len(self._chunks) - 1, -1, -1)
        weights = np.exp(-self.config.ensemble_decay * np.arange(len(self._chunks)))
        predictions = np.stack([c[:, j] for c, j in zip(self._chunks, ages, strict=True)])
        return np.tensordot(weights / weights.sum(), predictions, axes=1)

    def _mean(self, prediction: torch.Tensor) -> torch.Tensor:
        """An ensemble's stacked (K, ...) predictions as their mean; a single network's as they are."""
        return prediction.mean(dim=0) if self.config.members > 1 else prediction


def load(run: str | os.PathLike[str]) -> Policy:
    """The policy a `gym-fetch train` run holds (its last checkpoint)."""
    state = ckpt.read(run)
    config = PolicyConfig.from_dict(dict(state["policy"]))
    model = build(config)
    try:
        model.load_state_dict(state["model"])
    except RuntimeError as e:
        raise FetchError(f"{run}: the checkpoint's weights do not fit its policy settings: {e}") from e
    norm = Normalizer(state["norm"]["mean"].numpy(), state["norm"]["std"].numpy())
    source = state["source"]
    seeds = frozenset(int(s) for s in state["seeds"].tolist())
    horizon = state.get("horizon")
    return Policy(config, model, norm, str(source["env_id"]), json.loads(source["env_kwargs"]), seeds,
                  int(state["step"]), None if horizon is None else int(horizon))
