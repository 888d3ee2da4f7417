"""What training does unless told otherwise, decided in one place for `gym-fetch train` and Python callers.

A caller says what it wants in a `TrainRequest` (the CLI's flags, one field each; None and "auto" leave
the choice open); `plan` fills in the rest from the task's recipe (`fetch.learn.recipes`, the choices
measured best on it), the policy kind's defaults (`fetch.learn.kinds`) and, going on from a
run, that run's settings, and returns the `TrainPlan` that `fetch.learn.train.train` runs. No torch here.
"""

from __future__ import annotations

import dataclasses
import math
import os
import reprlib
from typing import Any

from fetch.dataset.habits import layout_of
from fetch.errors import FetchError
from fetch.learn.data import Demos, unseen_by_pixels, velocity_columns
from fetch.learn.kinds import AUTO, INPUTS, KINDS, PolicyConfig, PolicySettings, kind, pixel_kind, uses_pixels
from fetch.learn.recipes import Training, task_training

ACCELERATORS = ("auto", "cpu", "cuda")
PRECISIONS = ("auto", "fp32", "bf16")
"""How a training step computes: fp32, or bf16 (the network's matrix products and convolutions in bfloat16
under torch.autocast, the weights and the loss in fp32); auto is bf16 where the device computes it natively
(a CPU with AVX512-BF16 or AMX, a CUDA device that supports it), else fp32."""
FROM_STEPS_DIVISOR = 4
"""`train --from RUN` goes on for a quarter of RUN's steps unless told otherwise."""
CORRECTION_WEIGHT = 4
"""How many times each stretch a person drove in a corrected attempt counts among the training demos."""
MAX_TRAIN_STEPS = 10_000_000
"""The most gradient steps a run may take: 1000 times a task's default (5000-10000), days of training on a CPU;
a stranger's checkpoint cannot make `train --from` (a quarter of its steps) run on for ever."""


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
    precision: str = "fp32"
    """`PRECISIONS`; `train` decides "auto" for its device before the run starts (the checkpoint keeps which)."""

    def __post_init__(self) -> None:
        if not isinstance(self.precision, str) or self.precision not in PRECISIONS:
            raise FetchError(f"--precision {reprlib.repr(self.precision)}: choose one of {', '.join(PRECISIONS)}")
        for name in ("steps", "batch_size", "checkpoint_every", "threads"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise FetchError(f"--{name.replace('_', '-')} must be a whole number >= 1, got {reprlib.repr(value)}")
        if self.steps > MAX_TRAIN_STEPS:
            raise FetchError(f"--steps must be at most {MAX_TRAIN_STEPS}, got {self.steps}")
        for name in ("seed", "demos"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise FetchError(f"--{name} must be a whole number >= 0, got {reprlib.repr(value)}")
        if not isinstance(self.mirror, bool):
            raise FetchError(f"mirror must be true or false, got {reprlib.repr(self.mirror)}")
        for name in ("lr", "weight_decay", "obs_noise"):
            value = getattr(self, name)
            number = isinstance(value, int | float) and not isinstance(value, bool)
            if not (number and math.isfinite(value) and value >= 0) or (name == "lr" and value == 0):
                raise FetchError(f"--{name.replace('_', '-')} must be a finite number "
                                 f"{'> 0' if name == 'lr' else '>= 0'}, got {reprlib.repr(value)}")


POLICY_FLAGS = ("chunk", "seq_len", "hidden", "layers", "members", "goal_offsets", "velocities", "cameras",
                "finger_scale")
"""The `TrainRequest` fields that shape the policy (a run gone on from keeps its own)."""


@dataclasses.dataclass(frozen=True)
class TrainRequest:
    """What a caller asks of training: `gym-fetch train`'s flags, one field each. None (and `policy="auto"`)
    leaves the choice to `plan`."""

    policy: str = AUTO
    """a policy kind (`fetch.learn.kinds.POLICY_KINDS`), or "auto": the task's (`fetch.learn.recipes`), or
    with `inputs="pixels"` the pixel kind."""
    inputs: str = "state"
    """what the policy sees (`fetch.learn.kinds.INPUTS`): the state, or the cameras' images with the robot's
    own readings and the goal."""
    cameras: tuple[str, ...] | None = None
    """a pixel policy's cameras (None: every camera the demos have images of)."""
    steps: int | None = None
    epochs: int | None = None
    """passes over the training examples, instead of `steps`."""
    chunk: int | None = None
    seq_len: int | None = None
    finger_scale: float | None = None
    """None: `kinds.FINGER_SCALE`; 0 learns the fingers' action as recorded."""
    hidden: int | None = None
    layers: int | None = None
    members: int | None = None
    goal_offsets: bool | None = None
    velocities: bool | None = None
    mirror: bool | None = None
    demos: int = TrainConfig.demos
    batch_size: int | None = None
    """None: the kind's (`PolicyKind.training`), else `TrainConfig`'s."""
    lr: float = TrainConfig.lr
    obs_noise: float = TrainConfig.obs_noise
    seed: int = TrainConfig.seed
    checkpoint_every: int = TrainConfig.checkpoint_every
    threads: int | None = None
    """None: the kind's (`PolicyKind.training`; 0 there is one per core), else `TrainConfig`'s."""
    precision: str | None = None
    """`PRECISIONS`; None: the kind's (`PolicyKind.training`), else `TrainConfig`'s."""
    start_from: str | os.PathLike[str] | None = None
    """a run whose policy this one goes on training (`--from`): its settings, weights and normalisation."""
    accelerator: str = "auto"
    """where to train (`ACCELERATORS`): "auto" is CUDA where torch sees a device, else the CPU. Not part of
    the run's settings: a run stopped on one may resume on the other (results are reproducible for one
    device and thread count)."""

    def given(self) -> list[str]:
        """The policy-shaping fields this request sets, as flags."""
        return [f"--{n.replace('_', '-')}" for n in POLICY_FLAGS if getattr(self, n) is not None]


@dataclasses.dataclass(frozen=True)
class TrainPlan:
    """Everything a run needs decided: the policy, the training, and the run it goes on from (if any)."""

    policy: PolicySettings
    config: TrainConfig
    start_from: str | os.PathLike[str] | None = None


def cores() -> int:
    """The cores this process may run on."""
    from fetch._processes import usable_cores

    return usable_cores()


def sees_pixels(request: TrainRequest | TrainPlan, base: dict[str, Any] | None = None) -> bool:
    """Whether the run `request` asks for learns from camera images (so its demos are loaded with them).
    `base`: the checkpoint of `request.start_from`, whose policy a run going on from it keeps."""
    if isinstance(request, TrainPlan):
        return bool(request.policy.cameras)
    if base is not None:
        return bool(base["policy"].get("cameras"))
    return uses_pixels(request.policy, request.inputs)


def plan(request: TrainRequest, demos: Demos, base: dict[str, Any] | None = None) -> TrainPlan:
    """The run `request` asks for on `demos`. `base`: the checkpoint of `request.start_from` (read by the
    caller, which has torch), whose policy and mirroring the run keeps."""
    if request.start_from is not None:
        if base is None:
            raise FetchError("plan: going on from a run needs that run's checkpoint (base)")
        if request.given() or request.policy != AUTO:
            raise FetchError(f"--from {request.start_from} goes on with that run's policy; leave out "
                             f"{', '.join(request.given()) or '--policy'}")
        policy = PolicyConfig.from_dict(dict(base["policy"])).settings
        mirror = bool(base["train"].get("mirror", False)) if request.mirror is None else request.mirror
        steps = request.steps if request.steps is not None else _quarter(base)
    else:
        policy = _policy(request, demos)
        auto = task_training(demos.env_id) if request.policy == AUTO else None
        mirror = request.mirror if request.mirror is not None else bool(auto and auto.mirror and not policy.cameras)
        steps = request.steps if request.steps is not None else kind(policy.kind).training.get(
            "steps", task_training(demos.env_id).steps)
    if mirror and policy.cameras:
        raise FetchError("--mirror does not apply to a pixel policy: a camera's image of a demo is not the image "
                         "of its mirror image")
    for flag, owner in (("chunk", "mlp-chunk"), ("seq_len", "gru")):
        if getattr(request, flag) is not None and flag not in kind(policy.kind).own:
            raise FetchError(f"--{flag.replace('_', '-')} is for --policy {owner}; {request.policy} trains "
                             f"{policy.kind} here, which does not read it")
    own = kind(policy.kind).training
    batch_size = request.batch_size if request.batch_size is not None else own.get("batch_size",
                                                                                   TrainConfig.batch_size)
    threads = request.threads if request.threads is not None else own.get("threads", TrainConfig.threads)
    precision = request.precision if request.precision is not None else own.get("precision", TrainConfig.precision)
    if request.epochs is not None:
        if request.epochs < 1:
            raise FetchError(f"--epochs must be a whole number >= 1, got {request.epochs}")
        used = demos.train[:request.demos] if request.demos else demos.train
        count = sum(len(e.actions) for e in used)
        steps = request.epochs * max(1, count // max(1, min(batch_size, count)))
    config = TrainConfig(steps=steps, batch_size=batch_size, lr=request.lr, obs_noise=request.obs_noise,
                         seed=request.seed, demos=request.demos, mirror=mirror,
                         checkpoint_every=request.checkpoint_every, threads=threads or cores(),
                         precision=precision)
    return TrainPlan(policy, config, request.start_from)


def _quarter(base: dict[str, Any]) -> int:
    return max(1, int(base["train"]["steps"]) // FROM_STEPS_DIVISOR)


def _policy(request: TrainRequest, demos: Demos) -> PolicySettings:
    """The policy a new run trains: the kind's defaults, then the task's measured choices (auto), then
    what the request sets. A pixel policy sees, of the state, only what `data.unseen_by_pixels` leaves."""
    if request.inputs not in INPUTS:
        raise FetchError(f"--inputs {request.inputs!r}: choose one of {', '.join(INPUTS)}")
    chosen: dict[str, Any] = {}
    if request.policy == AUTO:
        auto = task_training(demos.env_id)
        pixels = uses_pixels(AUTO, request.inputs)
        name = pixel_kind().name if pixels else auto.policy
        chosen = {"goal_offsets": auto.goal_offsets, "velocities": auto.velocities}
        if not pixels:
            chosen["members"] = auto.members  # an ensemble of CNNs would take that many times as long
        if auto.chunk is not None and "chunk" in kind(name).own:
            chosen["chunk"] = auto.chunk
    else:
        name = kind(request.policy).name
        if request.inputs != "state" and kind(name).inputs != request.inputs:
            raise FetchError(f"--policy {name} sees the {kind(name).inputs}, not {request.inputs}; choose one of "
                             f"{', '.join(k.name for k in KINDS if k.inputs == request.inputs)} or --policy auto")
    for flag in POLICY_FLAGS:
        if getattr(request, flag) is not None:
            chosen[flag] = getattr(request, flag)
    layout = layout_of(demos.env_id) or {}
    velocities = chosen.pop("velocities", True)
    blind = set() if velocities else set(velocity_columns(layout))
    if uses_pixels(name):
        chosen["cameras"] = _cameras(chosen.get("cameras"), demos)
        blind |= set(unseen_by_pixels(layout, bool(chosen.get("goal_offsets", False))))
    elif chosen.get("cameras"):
        raise FetchError(f"--cameras is for a pixel policy (--inputs pixels); {name} sees the state")
    if blind:
        chosen["blind"] = tuple(sorted(blind))
    return PolicySettings.of(name, **chosen)


def _cameras(asked: tuple[str, ...] | None, demos: Demos) -> tuple[str, ...]:
    """The cameras a pixel policy sees: those asked for, each one the demos have images of (None: all)."""
    if not demos.cameras:
        raise FetchError(f"{demos.origin} holds no camera images for a pixel policy to learn from; record them with "
                         "`collect --cameras front,wrist` or `generate --cameras front,wrist`, or add them with "
                         "`gym-fetch render-obs DATASET --camera front`")
    cameras = tuple(asked) if asked else demos.cameras
    for camera in cameras:
        if camera not in demos.cameras:
            raise FetchError(f"--cameras {camera}: {demos.origin} has images of {', '.join(demos.cameras)} only")
    return cameras
