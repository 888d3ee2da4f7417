"""The torch side of each policy kind (`fetch.learn.kinds.KINDS` names them): network, examples, acting.

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
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple, Protocol, cast

import numpy as np
import torch
from torch import nn

from fetch._references import resolve
from fetch.errors import FetchError
from fetch.learn.data import Episode, chunk_targets, learnt_actions, policy_inputs
from fetch.learn.kinds import PolicyConfig, kind

ACTION_SIZE = 4
Examples = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Training examples: inputs X, targets Y, and which targets exist M."""


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
        network = implementation(config.kind).network
        self.nets = nn.ModuleList(network(config) for _ in range(config.members))

    def forward(self, x: torch.Tensor, *images: torch.Tensor) -> torch.Tensor:
        return torch.stack([net(x, *images) for net in self.nets])

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
    """Training examples of one policy kind: inputs X, targets Y, and which targets exist M; for a pixel
    policy, the camera images of each example (one (N, H, W, 3) uint8 array per camera) and what it does
    not see of the state, normalised (N, len(blind)): its encoder's auxiliary targets."""

    x: np.ndarray
    y: np.ndarray
    m: np.ndarray
    images: tuple[np.ndarray, ...] = ()
    unseen: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.x)

    def tensors(self) -> Batch:
        """All of them as tensors, sharing memory with the arrays."""
        return Batch(torch.from_numpy(self.x), torch.from_numpy(self.y), torch.from_numpy(self.m),
                     tuple(torch.from_numpy(v) for v in self.images),
                     None if self.unseen is None else torch.from_numpy(self.unseen))


class Batch(NamedTuple):
    """Examples as tensors (`Samples.tensors`), or some of them (`take`)."""

    x: torch.Tensor
    y: torch.Tensor
    m: torch.Tensor
    images: tuple[torch.Tensor, ...]
    unseen: torch.Tensor | None

    def take(self, index: torch.Tensor | slice) -> Batch:
        return Batch(self.x[index], self.y[index], self.m[index], tuple(v[index] for v in self.images),
                     None if self.unseen is None else self.unseen[index])

    def to(self, device: torch.device) -> Batch:
        if device.type == "cpu":
            return self
        return Batch(self.x.to(device), self.y.to(device), self.m.to(device), tuple(v.to(device) for v in self.images),
                     None if self.unseen is None else self.unseen.to(device))


def samples(config: PolicyConfig, episodes: Sequence[Episode], normalize: Any) -> Samples:
    """Every training example of `episodes`, inputs normalised by `normalize`."""
    kind_ = implementation(config.kind)
    xs, ys, ms = [], [], []
    for e in episodes:
        x, y, m = kind_.examples(config, normalize(policy_inputs(e, config.goal_offsets, config.blind)),
                                 learnt_actions(e.actions, config.finger_scale, config.finger_span))
        xs.append(x)
        ys.append(y)
        ms.append(m)
    images = tuple(np.concatenate([e.images[c] for e in episodes]) for c in config.cameras)
    unseen = None
    if kind_.learns_unseen and config.blind:
        whole = np.concatenate([policy_inputs(e, config.goal_offsets) for e in episodes])[:, list(config.blind)]
        unseen = ((whole - whole.mean(axis=0)) / np.maximum(whole.std(axis=0), 1e-2)).astype(np.float32)
    return Samples(np.concatenate(xs), np.concatenate(ys), np.concatenate(ms), images, unseen)


def build(config: PolicyConfig) -> nn.Module:
    return Members(config) if config.members > 1 else implementation(config.kind).network(config)


def masked_loss(config: PolicyConfig, prediction: torch.Tensor, target: torch.Tensor,
                mask: torch.Tensor) -> torch.Tensor:
    """The mean error of the targets that exist; an ensemble's (K, ...) predictions: the mean over members."""
    error = (prediction - target).abs() if config.loss == "l1" else (prediction - target) ** 2
    if config.members > 1:
        error = error.mean(dim=0)
    weights = mask.unsqueeze(-1).to(error.dtype)
    return (error * weights).sum() / (weights.sum() * ACTION_SIZE).clamp_min(1.0)


def behaviour_loss(config: PolicyConfig, model: nn.Module, batch: Batch) -> torch.Tensor:
    """How far the policy's predicted actions are from the demos' (`masked_loss`)."""
    return masked_loss(config, model(batch.x, *batch.images), batch.y, batch.m)


def member_mean(config: PolicyConfig, prediction: torch.Tensor) -> torch.Tensor:
    """An ensemble's stacked (K, ...) predictions as their mean; a single network's as they are."""
    return prediction.mean(dim=0) if config.members > 1 else prediction


class Actor(Protocol):
    """How a policy of one kind acts on a batch of normalised inputs (B, D), and for a pixel policy its
    cameras' (B, H, W, 3) uint8 images, step after step."""

    def reset(self) -> None:
        """New episodes start."""

    def __call__(self, x: torch.Tensor, *images: torch.Tensor) -> np.ndarray:
        """(B, D) inputs of this step (and its images) -> (B, 4) actions."""

    @property
    def spread(self) -> np.ndarray | None:
        """(B,) after a call: how far apart the predictions this step's action was made from lie, the largest
        standard deviation over the hand's three action entries (`hand_spread`); None where the action came
        from one prediction. Cheap, so the window can show a person where the policy is unsure."""


class ChunkActor:
    """Predicts a chunk of actions every `act_steps` steps and acts at each step on the weighted mean of what
    every chunk still covering it predicted for it (ACT's temporal ensembling; ACT predicts every step)."""

    def __init__(self, config: PolicyConfig, model: nn.Module) -> None:
        self.config, self.model = config, model
        self.reset()

    def reset(self) -> None:
        self._chunks: list[np.ndarray] = []  # newest last, each (B, chunk, 4)
        self._made: list[int] = []  # the step each was predicted at
        self._t = 0
        self.spread: np.ndarray | None = None
        """the chunks' disagreement over this step (`Actor.spread`): None until two chunks cover it."""

    def __call__(self, x: torch.Tensor, *images: torch.Tensor) -> np.ndarray:
        t, chunk = self._t, self.config.chunk
        if t % self.config.act_steps == 0:
            self._chunks.append(member_mean(self.config, self.model(x, *images)).numpy())
            self._made.append(t)
        while t - self._made[0] >= chunk:  # it no longer covers this step
            del self._chunks[0], self._made[0]
        self._t += 1
        # The chunk made j steps ago predicted this step as its element j; the oldest weighs most.
        weights = np.exp(-self.config.ensemble_decay * np.arange(len(self._chunks)))
        predictions = np.stack([c[:, t - made] for c, made in zip(self._chunks, self._made, strict=True)])
        self.spread = hand_spread(predictions) if len(predictions) > 1 else None
        return np.tensordot(weights / weights.sum(), predictions, axes=1)


class RecurrentActor:
    """Carries the hidden state from step to step, restarted every `seq_len` steps as in training."""

    def __init__(self, config: PolicyConfig, model: nn.Module) -> None:
        self.config, self.model = config, cast(RecurrentPolicy | Members, model)
        self.reset()

    def reset(self) -> None:
        self._t = 0
        self._hidden: Any = None  # an ensemble's: one per member
        self.spread: np.ndarray | None = None
        """the members' disagreement (`Actor.spread`): None for a single network."""

    def __call__(self, x: torch.Tensor, *images: torch.Tensor) -> np.ndarray:
        if self._t % self.config.seq_len == 0:
            self._hidden = None
        self._t += 1
        out, self._hidden = self.model.step(x[:, None, :], self._hidden)
        if self.config.members > 1:
            self.spread = hand_spread(out[:, :, 0].numpy())
        return member_mean(self.config, out)[:, 0].numpy()


def hand_spread(predictions: np.ndarray) -> np.ndarray:
    """(B,) of (N, B, 4) predictions of one step's action: the largest standard deviation over the hand's three
    entries [action units; 0.1 is 5 mm of hand target]. The fingers' entry is left out: it is learnt companded,
    so its spread reads on another scale."""
    return predictions[..., :3].std(axis=0).max(axis=-1)


def chunk_examples(config: PolicyConfig, obs: np.ndarray, actions: np.ndarray) -> Examples:
    """One example per step: its observation, and the next `chunk` actions (masked past the demo's end)."""
    y, m = chunk_targets(actions, config.chunk)
    return obs, y, m


def _window_examples(config: PolicyConfig, obs: np.ndarray, actions: np.ndarray) -> Examples:
    """A window of `seq_len` steps starting at every step; past the demo's end the last observation
    repeats, masked out."""
    x, m = chunk_targets(obs, config.seq_len)
    y, _ = chunk_targets(actions, config.seq_len)
    return x, y, m


@dataclasses.dataclass(frozen=True)
class Kind:
    """A policy kind's torch side, named by its `fetch.learn.kinds.PolicyKind.implementation`."""

    network: Callable[[PolicyConfig], nn.Module]
    """one network of the kind (`build` makes an ensemble of them)."""
    examples: Callable[[PolicyConfig, np.ndarray, np.ndarray], Examples]
    """a demo's (T, D) normalised inputs and (T, 4) actions -> its training examples X, Y, M."""
    actor: Callable[[PolicyConfig, nn.Module], Actor]
    loss: Callable[[PolicyConfig, nn.Module, Batch], torch.Tensor] = behaviour_loss
    """what training minimises on a batch."""
    learns_unseen: bool = False
    """its examples carry what it does not see of the state (`Samples.unseen`), for its loss."""


CHUNKED = Kind(ChunkMLP, chunk_examples, ChunkActor)
RECURRENT = Kind(RecurrentPolicy, _window_examples, RecurrentActor)


def implementation(kind_name: str) -> Kind:
    """The torch side of the kind `kind_name`."""
    found = resolve(kind(kind_name).implementation)
    if not isinstance(found, Kind):
        raise FetchError(f"policy kind {kind_name}: {kind(kind_name).implementation} is not a policies.Kind")
    return found
