"""What training does unless told otherwise, decided in one place for `gym-fetch train` and Python callers.

A caller says what it wants in a `TrainRequest` (the CLI's flags, one field each; None and "auto" leave
the choice open); `plan` fills in the rest from the task's line in the task table (`fetch.tasks.Training`,
the choices measured best on it), the policy kind's defaults (`fetch.learn.kinds`) and, going on from a
run, that run's settings, and returns the `TrainPlan` that `fetch.learn.train.train` runs. No torch here.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

from fetch.dataset.habits import layout_of
from fetch.errors import FetchError
from fetch.learn.data import Demos, velocity_columns
from fetch.learn.kinds import PolicySettings, kind
from fetch.tasks import Training, registration

AUTO = "auto"
FROM_STEPS_DIVISOR = 4
"""`train --from RUN` goes on for a quarter of RUN's steps unless told otherwise."""
CORRECTION_WEIGHT = 4
"""How many times each stretch a person drove in a corrected attempt counts among the training demos."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """How a policy is trained (stored in the checkpoint; a resumed run must ask for the same)."""

    steps: int = Training().steps
    """Gradient steps in all."""
    batch_size: int = 256
    lr: float = 1e-3
    """[1] Adam's peak learning rate; it decays to 0 along a cosine over `steps`."""
    weight_decay: float = 1e-4
    obs_noise: float = 0.0
    """Std of Gaussian noise added to the normalised observations while training (0: none)."""
    seed: int = 0
    demos: int = 0
    """Train on the first `demos` of mask/train (0: all)."""
    mirror: bool = False
    """Also learn from each training demo's mirror image (`data.with_reflections`; symmetric tasks only)."""
    checkpoint_every: int = 1000
    """[steps] between checkpoints (and validation losses); one is also written at the end."""
    threads: int = 1
    """torch's intra-op threads: results are reproducible for a given count."""

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size", "checkpoint_every", "threads"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise FetchError(f"--{name.replace('_', '-')} must be a whole number >= 1, got {value!r}")
        for name in ("seed", "demos"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 0:
                raise FetchError(f"--{name} must be a whole number >= 0, got {value!r}")
        for name in ("lr", "weight_decay", "obs_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0) or (name == "lr" and value == 0):
                raise FetchError(f"--{name.replace('_', '-')} must be a finite number "
                                 f"{'> 0' if name == 'lr' else '>= 0'}, got {value!r}")


POLICY_FLAGS = ("chunk", "seq_len", "hidden", "layers", "members", "goal_offsets", "velocities")
"""The `TrainRequest` fields that shape the policy (a run gone on from keeps its own)."""


@dataclasses.dataclass(frozen=True)
class TrainRequest:
    """What a caller asks of training: `gym-fetch train`'s flags, one field each. None (and `policy="auto"`)
    leaves the choice to `plan`."""

    policy: str = AUTO
    """a policy kind (`fetch.learn.kinds.POLICY_KINDS`), or "auto": the task's (`fetch.tasks.Training`)."""
    steps: int | None = None
    epochs: int | None = None
    """passes over the training examples, instead of `steps`."""
    chunk: int | None = None
    seq_len: int | None = None
    hidden: int | None = None
    layers: int | None = None
    members: int | None = None
    goal_offsets: bool | None = None
    velocities: bool | None = None
    mirror: bool | None = None
    demos: int = TrainConfig.demos
    batch_size: int = TrainConfig.batch_size
    lr: float = TrainConfig.lr
    obs_noise: float = TrainConfig.obs_noise
    seed: int = TrainConfig.seed
    checkpoint_every: int = TrainConfig.checkpoint_every
    threads: int = TrainConfig.threads
    start_from: str | os.PathLike[str] | None = None
    """a run whose policy this one goes on training (`--from`): its settings, weights and normalisation."""

    def given(self) -> list[str]:
        """The policy-shaping fields this request sets, as flags."""
        return [f"--{n.replace('_', '-')}" for n in POLICY_FLAGS if getattr(self, n) is not None]


@dataclasses.dataclass(frozen=True)
class TrainPlan:
    """Everything a run needs decided: the policy, the training, and the run it goes on from (if any)."""

    policy: PolicySettings
    config: TrainConfig
    start_from: str | os.PathLike[str] | None = None


def task_training(env_id: str) -> Training:
    """What `--policy auto` trains on `env_id` unless told otherwise (its line in the task table)."""
    return registration(env_id).training


def plan(request: TrainRequest, demos: Demos, base: dict[str, Any] | None = None) -> TrainPlan:
    """The run `request` asks for on `demos`. `base`: the checkpoint of `request.start_from` (read by the
    caller, which has torch), whose policy and mirroring the run keeps."""
    if request.start_from is not None:
        if base is None:
            raise FetchError("plan: going on from a run needs that run's checkpoint (base)")
        if request.given() or request.policy != AUTO:
            raise FetchError(f"--from {request.start_from} goes on with that run's policy; leave out "
                             f"{', '.join(request.given()) or '--policy'}")
        policy = PolicySettings(**{k: v for k, v in base["policy"].items() if k != "obs_size"})
        mirror = bool(base["train"].get("mirror", False)) if request.mirror is None else request.mirror
        steps = request.steps if request.steps is not None else _quarter(base)
    else:
        policy = _policy(request, demos.env_id)
        auto = task_training(demos.env_id) if request.policy == AUTO else None
        mirror = request.mirror if request.mirror is not None else bool(auto and auto.mirror)
        steps = request.steps if request.steps is not None else task_training(demos.env_id).steps
    for flag, owner in (("chunk", "mlp-chunk"), ("seq_len", "gru")):
        if getattr(request, flag) is not None and flag not in kind(policy.kind).own:
            raise FetchError(f"--{flag.replace('_', '-')} is for --policy {owner}; {request.policy} trains "
                             f"{policy.kind} here, which does not read it")
    if request.epochs is not None:
        if request.epochs < 1:
            raise FetchError(f"--epochs must be a whole number >= 1, got {request.epochs}")
        used = demos.train[:request.demos] if request.demos else demos.train
        count = sum(len(e.actions) for e in used)
        steps = request.epochs * max(1, count // max(1, min(request.batch_size, count)))
    config = TrainConfig(steps=steps, batch_size=request.batch_size, lr=request.lr, obs_noise=request.obs_noise,
                         seed=request.seed, demos=request.demos, mirror=mirror,
                         checkpoint_every=request.checkpoint_every, threads=request.threads)
    return TrainPlan(policy, config, request.start_from)


def _quarter(base: dict[str, Any]) -> int:
    return max(1, int(base["train"]["steps"]) // FROM_STEPS_DIVISOR)


def _policy(request: TrainRequest, env_id: str) -> PolicySettings:
    """The policy a new run trains: the kind's defaults, then the task's measured choices (auto), then
    what the request sets."""
    chosen: dict[str, Any] = {}
    if request.policy == AUTO:
        auto = task_training(env_id)
        name = auto.policy
        chosen = {"members": auto.members, "goal_offsets": auto.goal_offsets, "velocities": auto.velocities}
        if auto.chunk is not None:
            chosen["chunk"] = auto.chunk
    else:
        name = kind(request.policy).name
    for flag in POLICY_FLAGS:
        if getattr(request, flag) is not None:
            chosen[flag] = getattr(request, flag)
    velocities = chosen.pop("velocities", True)
    if not velocities:
        chosen["blind"] = velocity_columns(layout_of(env_id) or {})
    return PolicySettings.of(name, **chosen)
