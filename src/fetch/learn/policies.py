"""Policy networks for low-dimensional state, and the one table (`POLICIES`) that names them.

Every policy maps a batch of inputs X to predictions of the same shape as its targets Y, where
only the entries M marks count in the loss. `mlp-chunk` reads one observation (N, D) and predicts
the next `chunk` actions (N, chunk, 4), as ACT does; `gru` reads a window of `seq_len`
observations (N, L, D) and predicts the action at each of them (N, L, 4), as robomimic's BC-RNN.
Either can be an ensemble (`members` > 1): that many networks of the kind, from different initial
weights, trained side by side on the same batches; their predictions are stacked on a leading axis
(K, ...), each is trained against the targets, and the policy acts on their mean.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from fetch.errors import FetchError, UnknownNameError
from fetch.learn.data import Episode, chunk_targets, policy_inputs

ACTION_SIZE = 4


@dataclasses.dataclass(frozen=True)
class PolicyConfig:
    """What a policy is: its kind, sizes, and how it acts (stored in every checkpoint as plain values)."""

    kind: str
    obs_size: int
    hidden: int = 256
    layers: int = 2
    chunk: int = 10
    """mlp-chunk: actions predicted per observation (1: plain behaviour cloning)."""
    ensemble_decay: float = 0.01
    """mlp-chunk: ACT's temporal-ensembling weight exp(-decay * i), i = 0 for the oldest prediction."""
    seq_len: int = 10
    """gru: training window [steps]; acting, the hidden state restarts every `seq_len` steps as in training."""
    loss: str = "l1"
    members: int = 1
    """networks trained side by side from different initial weights; the policy acts on their mean."""
    goal_offsets: bool = False
    """also see the goal relative to the achieved goal and to the grip site (`data.with_goal_offsets`)."""
    blind: tuple[int, ...] = ()
    """entries of the input the policy does not see (set to 0 before normalising): the observation's
    velocities with `--no-velocities` (`data.velocity_columns`)."""

    def __post_init__(self) -> None:
        if self.kind not in POLICIES:
            raise UnknownNameError("policy", self.kind, tuple(POLICIES))
        if self.loss not in LOSSES:
            raise UnknownNameError("loss", self.loss, LOSSES)
        for name in ("obs_size", "hidden", "layers", "chunk", "seq_len", "members"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise FetchError(f"policy {name} must be a whole number >= 1, got {value!r}")
        if not isinstance(self.goal_offsets, bool):
            raise FetchError(f"goal_offsets must be true or false, got {self.goal_offsets!r}")
        object.__setattr__(self, "blind", tuple(self.blind))  # a checkpoint may hold a list
        if not all(isinstance(i, int) and 0 <= i < self.obs_size for i in self.blind):
            raise FetchError(f"blind must list input entries 0..{self.obs_size - 1}, got {list(self.blind)}")
        if not self.ensemble_decay >= 0:
            raise FetchError(f"ensemble_decay must be >= 0, got {self.ensemble_decay!r}")

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, raw: dict[str, Any]) -> PolicyConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(raw) - known
        if unknown:
            raise FetchError(f"unknown policy settings {sorted(unknown)}; known: {sorted(known)}")
        return cls(**raw)


LOSSES = ("l1", "mse")
KIND_DEFAULTS: dict[str, dict[str, Any]] = {"mlp-chunk": {}, "gru": {"hidden": 128, "layers": 1}}
"""Settings of a kind that differ from `PolicyConfig`'s defaults (a GRU of 256 trains 4x slower on a CPU)."""


class ChunkMLP(nn.Module):
    """Observation -> the next `chunk` actions."""

    def __init__(self, config: PolicyConfig) -> None:
        super().__init__()
        self.chunk = config.chunk
        sizes = [config.obs_size] + [config.hidden] * config.layers
        body: list[nn.Module] = []
        for a, b in zip(sizes[:-1], sizes[1:], strict=True):
            body += [nn.Linear(a, b), nn.ReLU()]
        self.net = nn.Sequential(*body, nn.Linear(sizes[-1], config.chunk * ACTION_SIZE))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x).reshape(*x.shape[:-1], self.chunk, ACTION_SIZE)


class RecurrentPolicy(nn.Module):
    """Observations in order -> an action at each: an encoder, a GRU, a linear head."""

    def __init__(self, config: PolicyConfig) -> None:
        super().__init__()
        self.encoder = nn.Sequential(nn.Linear(config.obs_size, config.hidden), nn.ReLU())
        self.gru = nn.GRU(config.hidden, config.hidden, num_layers=config.layers, batch_first=True)
        self.head = nn.Linear(config.hidden, ACTION_SIZE)

    def forward(self, x: torch.Tensor, hidden: torch.Tensor | None = None) -> torch.Tensor:
        return self.step(x, hidden)[0]

    def step(self, x: torch.Tensor, hidden: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, L, D) inputs and the hidden state (None: zeros) -> (N, L, 4) actions, the new hidden state."""
        out, hidden = self.gru(self.encoder(x), hidden)
        return self.head(out), hidden


class Members(nn.Module):
    """`config.members` networks of one kind: their predictions stacked on a leading axis (K, ...)."""

    def __init__(self, config: PolicyConfig) -> None:
        super().__init__()
        self.nets = nn.ModuleList(POLICIES[config.kind](config) for _ in range(config.members))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.stack([net(x) for net in self.nets])

    def step(self, x: torch.Tensor, hidden: list[torch.Tensor] | None) -> tuple[torch.Tensor, list[torch.Tensor]]:
        """The recurrent members' `step`, each with its own hidden state."""
        outs, states = [], []
        for i, net in enumerate(self.nets):
            out, state = cast(RecurrentPolicy, net).step(x, None if hidden is None else hidden[i])
            outs.append(out)
            states.append(state)
        return torch.stack(outs), states


@dataclasses.dataclass(frozen=True)
class Samples:
    """Training examples of one policy kind: inputs X, targets Y, and which targets exist M."""

    x: np.ndarray
    y: np.ndarray
    m: np.ndarray

    def __len__(self) -> int:
        return len(self.x)


def samples(config: PolicyConfig, episodes: Sequence[Episode], normalize: Any) -> Samples:
    """Every training example of `episodes`, inputs normalised by `normalize`."""
    xs, ys, ms = [], [], []
    for e in episodes:
        obs = normalize(policy_inputs(e, config.goal_offsets, config.blind))
        if config.kind == "gru":
            # A window starts at every step; past the demo's end the last observation repeats, masked out.
            x, m = chunk_targets(obs, config.seq_len)
            y, _ = chunk_targets(e.actions, config.seq_len)
        else:
            x = obs
            y, m = chunk_targets(e.actions, config.chunk)
        xs.append(x)
        ys.append(y)
        ms.append(m)
    return Samples(np.concatenate(xs), np.concatenate(ys), np.concatenate(ms))


def build(config: PolicyConfig) -> nn.Module:
    return Members(config) if config.members > 1 else POLICIES[config.kind](config)


def masked_loss(config: PolicyConfig, prediction: torch.Tensor, target: torch.Tensor,
                mask: torch.Tensor) -> torch.Tensor:
    """The mean error of the targets that exist; an ensemble's (K, ...) predictions: the mean over members."""
    error = (prediction - target).abs() if config.loss == "l1" else (prediction - target) ** 2
    if config.members > 1:
        error = error.mean(dim=0)
    weights = mask.unsqueeze(-1).to(error.dtype)
    return (error * weights).sum() / (weights.sum() * ACTION_SIZE).clamp_min(1.0)


POLICIES: dict[str, type[nn.Module]] = {"mlp-chunk": ChunkMLP, "gru": RecurrentPolicy}
"""`--policy` choices: the network of each."""
