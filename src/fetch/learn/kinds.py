"""The kinds of policy `gym-fetch train` learns: one record each (`KINDS`), and the settings of a policy.

A kind's record says what it is for `--help`, what it sees (the state, or camera images with the robot's
own readings: `inputs`), which settings it reads that others do not, its defaults and how it trains unless
told, and where its torch side lives (`implementation`, resolved only when a policy is built or run): the
network, how a demo becomes training examples, and how the policy acts step by step
(`fetch.learn.policies.Kind`). A new kind is one record here and one `Kind` there. Nothing here imports
torch, so the CLI can list the kinds without it.
"""

from __future__ import annotations

import dataclasses
import math
import reprlib
import sys
from collections.abc import Mapping
from typing import Any

from fetch.errors import FetchError, UnknownNameError
from fetch.rendering import IMAGE_QUALITIES, MAX_IMAGE_SIZE


@dataclasses.dataclass(frozen=True)
class PolicyKind:
    name: str
    """`--policy NAME`."""
    summary: str
    """what it is, for `--help`."""
    own: tuple[str, ...]
    """the `PolicySettings` only this kind reads: a flag for one of them is refused for other kinds."""
    defaults: Mapping[str, Any]
    """its settings where they differ from `PolicySettings`' defaults."""
    implementation: str
    """its torch side, "module:attribute" (`fetch._references`): a `fetch.learn.policies.Kind`."""
    training: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    """how it trains unless told, where that differs from `TrainConfig`'s defaults and the task's steps
    (`steps`, `batch_size`, `threads`: 0 is one per core)."""
    inputs: str = "state"
    """what it sees: "state" (the observation vector and the goal) or "pixels" (camera images, the
    robot's own readings and the goal: `fetch.learn.data.PROPRIOCEPTION`)."""


PIXEL_ENSEMBLE_DECAY = -1.0
"""cnn-chunk's `ensemble_decay`: each newer chunk weighs e times the one before (the newest about 63 %), where
ACT weighs them all nearly alike (0.01). A chunk predicted steps ago saw the object from farther off, where the
images place it to 1-3 cm; averaged in alike, those guesses brought the hand down beside the block. On 300
unseen seeds, Bin-place from the `person` stand-in's demos 87.3 -> 92.3 %, from `standin`'s 94.7 -> 95.7 %
(docs/training.md, "Why these defaults")."""

PIXEL_ACT_STEPS = 2
"""cnn-chunk's `act_steps`: a chunk every other step. Predicting every step and acting mostly on the newest, a
policy whose demos paused after the grasp procrastinated at the still scene (each new chunk: "wait two steps, then
lift"); every other step the older chunk's lift carries the hand on (Bin-place from the `regrasp` stand-in's demos
80 -> 95 %; every fourth step loses precision; docs/training.md, "Why these defaults")."""

KINDS: tuple[PolicyKind, ...] = (
    PolicyKind("gru", "a recurrent policy (BC-RNN): reads a window of observations, one action per step",
               own=("seq_len",), defaults={"hidden": 128, "layers": 1},  # a GRU of 256 trains 4x slower on a CPU
               implementation="fetch.learn.policies:RECURRENT"),
    PolicyKind("mlp-chunk", "an MLP predicting chunks of actions with ACT's temporal ensembling, ~7x faster to "
               "train", own=("chunk", "ensemble_decay", "act_steps"), defaults={},
               implementation="fetch.learn.policies:CHUNKED"),
    PolicyKind("cnn-chunk", "sees camera images (a small convolutional encoder per camera, trained from scratch on "
               "randomly shifted images), the robot's own readings and the goal, not the objects' state; predicts "
               "chunks of actions as mlp-chunk", own=("chunk", "ensemble_decay", "act_steps", "cameras"),
               defaults={"ensemble_decay": PIXEL_ENSEMBLE_DECAY, "act_steps": PIXEL_ACT_STEPS},
               implementation="fetch.learn.pixels:PIXEL_CHUNK", inputs="pixels",
               # convolutions over images: a quarter of the batch, and every core (docs/training.md)
               training={"steps": 6000, "batch_size": 64, "threads": 0, "precision": "auto"}),
)
INPUTS = ("state", "pixels")
"""What a policy can see (`PolicyKind.inputs`; `gym-fetch train --inputs`)."""
POLICY_KINDS: tuple[str, ...] = tuple(k.name for k in KINDS)
_BY_NAME = {k.name: k for k in KINDS}


def kind(name: str) -> PolicyKind:
    if not isinstance(name, str) or name not in _BY_NAME:
        raise UnknownNameError("policy", name, POLICY_KINDS)
    return _BY_NAME[name]


AUTO = "auto"
"""`--policy auto`: the kind the task's recipe names (`fetch.learn.recipes`), or with `--inputs pixels` the
pixel kind (`pixel_kind`)."""


def pixel_kind() -> PolicyKind:
    """The kind that learns from camera images (what `--policy auto --inputs pixels` trains)."""
    return next(k for k in KINDS if k.inputs == "pixels")


def uses_pixels(policy: str, inputs: str = "state") -> bool:
    """Whether a run of kind `policy` (or "auto", `AUTO`) asked to see `inputs` learns from camera images:
    `inputs` "pixels" asks for them whatever the kind (a state kind asked for them is refused when the run
    is planned), a pixel kind sees them whatever `inputs`. The one place "pixels or state" is decided:
    `gym-fetch train`, `settings.plan` and a policy's own settings ask here."""
    return inputs == "pixels" or (policy != AUTO and kind(policy).inputs == "pixels")


LOSSES = ("l1", "mse")
FINGER_SCALE = 0.05
"""[a[3] units, m of finger target] what `PolicySettings.finger_scale` is unless told: a finger's travel. The
fingers' servo values (`Expert.finger_servo`: the opening wanted less the opening now) lie within it; the
squeeze, -1, beyond. Learnt as recorded, the servo's few hundredths were lost beside the squeeze and the
hand's +-1: on Bin-pick (100 DART expert demos, gru) 74 % as recorded, 98 % companded; the pixel policy on the bin
tasks about 2 points more (docs/training.md)."""
FINGER_SPAN = 0.5
"""What `PolicySettings.finger_span` is unless told: +-`finger_scale` of a[3] is learnt as +-0.5, the squeeze
as -1, so a[3] weighs in the loss about as it does recorded. Spanning +-1 (the squeeze at -2) made a[3] weigh
several times the hand's moves around the grasp: on PickPlace from `pauses` pad demos the policy then rested
with the block grasped (78 % against 86 % recorded and 87 % at 0.5, 400 episodes), while Bin-pick's gain held
(97.4 % at both spans; docs/training.md)."""


MAX_SIZES: Mapping[str, int] = {"hidden": 4096, "layers": 16, "members": 32, "chunk": 250, "seq_len": 250}
"""The most each size setting may be: 16 times the widest default (256 units; a 4096-wide layer is 16.8 M
weights, 67 MB), 8 times the deepest (2 layers), 6 times the largest ensemble a task trains (5); a chunk or
a window of 250 steps is 10 s at the control rate, 5 times a task's horizon (acting keeps `chunk` chunks of
`chunk` actions per episode: 50 episodes at once, 50 MB). Far beyond what a policy is trained with, far below
what would exhaust memory when a checkpoint from a stranger is built; a checkpoint's weights are also checked
against the network its settings describe before it is built (`fetch.learn.checked`)."""
MAX_INPUTS = 1024
"""The most entries a policy's input may have: 27 times the largest task's (Bin-pick, its goal offsets included:
37)."""
MAX_ENSEMBLE_DECAY = math.log(sys.float_info.max) / MAX_SIZES["chunk"]
"""|ensemble_decay| at most this (about 2.8; the kinds use 0.01 and -1): the weights exp(-decay * i) of up to
`MAX_SIZES["chunk"]` chunks stay within a float."""


def _whole(name: str, value: object, low: int, high: int) -> None:
    """FetchError unless `value` is a whole number (not a bool) from `low` to `high`."""
    if not isinstance(value, int) or isinstance(value, bool) or value < low:
        raise FetchError(f"policy {name} must be a whole number >= {low}, got {reprlib.repr(value)}")
    if value > high:
        raise FetchError(f"policy {name} must be at most {high}, got {value}")


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


@dataclasses.dataclass(frozen=True)
class PolicySettings:
    """What a policy is, but for the size of its input: its kind, sizes, and how it acts. Plain values,
    stored in every checkpoint (with the input size: `PolicyConfig`)."""

    kind: str
    hidden: int = 256
    """units per layer."""
    layers: int = 2
    chunk: int = 10
    """mlp-chunk: actions predicted per observation (1: plain behaviour cloning)."""
    ensemble_decay: float = 0.01
    """mlp-chunk: ACT's temporal-ensembling weight exp(-decay * i), i = 0 for the oldest prediction; below 0
    the newer predictions weigh more (`PIXEL_ENSEMBLE_DECAY`)."""
    act_steps: int = 1
    """chunk kinds: a chunk is predicted every this many steps (at most `chunk`), each step acting on what the
    chunks covering it predicted (1: every step, as ACT; `PIXEL_ACT_STEPS`)."""
    seq_len: int = 10
    """gru: training window [steps]; acting, the hidden state restarts every `seq_len` steps as in training."""
    loss: str = "l1"
    members: int = 1
    """networks trained side by side from different initial weights; the policy acts on their mean."""
    goal_offsets: bool = False
    """also see the goal relative to the achieved goal and to the grip site (`data.with_goal_offsets`)."""
    blind: tuple[int, ...] = ()
    """entries of the input the policy does not see (set to 0 before normalising): the observation's
    velocities with `--no-velocities` (`data.velocity_columns`); for a pixel policy, every entry but the
    robot's own readings and the goal (`data.unseen_by_pixels`)."""
    cameras: tuple[str, ...] = ()
    """pixel policies: the cameras whose images it sees, in this order (the dataset's `<camera>_image`)."""
    finger_scale: float = FINGER_SCALE
    """the fingers' action a[3] is learnt companded (`data.learnt_actions`): |a[3]| up to this spans
    +-`finger_span` and the rest of [-1, 1] the rest; 0: as recorded (runs saved before it existed)."""
    finger_span: float = FINGER_SPAN
    """companded, what +-`finger_scale` of a[3] is learnt as (the squeeze as twice it); runs saved before it
    existed: 1."""

    def __post_init__(self) -> None:
        kind(self.kind)
        if not isinstance(self.loss, str) or self.loss not in LOSSES:
            raise UnknownNameError("loss", self.loss, LOSSES)
        for name, most in MAX_SIZES.items():
            _whole(name, getattr(self, name), 1, most)
        if not isinstance(self.goal_offsets, bool):
            raise FetchError(f"goal_offsets must be true or false, got {reprlib.repr(self.goal_offsets)}")
        for name in ("blind", "cameras"):
            if not isinstance(getattr(self, name), tuple | list):
                raise FetchError(f"policy {name} must be a list, got {reprlib.repr(getattr(self, name))}")
        object.__setattr__(self, "blind", tuple(self.blind))  # a checkpoint may hold a list
        object.__setattr__(self, "cameras", tuple(self.cameras))
        pixels = uses_pixels(self.kind)
        if pixels and not self.cameras:
            raise FetchError(f"a {self.kind} policy sees camera images: name at least one camera")
        if not pixels and self.cameras:
            raise FetchError(f"a {self.kind} policy sees the state, not cameras ({', '.join(self.cameras)}); "
                             "a pixel policy: --inputs pixels")
        if not all(isinstance(c, str) and c for c in self.cameras) or len(set(self.cameras)) != len(self.cameras):
            raise FetchError(f"cameras must be distinct camera names, got {list(self.cameras)}")
        if not all(isinstance(i, int) and not isinstance(i, bool) and i >= 0 for i in self.blind):
            raise FetchError(f"blind must list input entries (whole numbers >= 0), got {reprlib.repr(self.blind)}")
        if not _number(self.finger_scale) or not 0.0 <= self.finger_scale < 1.0:
            raise FetchError(f"finger_scale must be at least 0 and below 1, got {reprlib.repr(self.finger_scale)}")
        if not _number(self.finger_span) or not 0.0 < self.finger_span <= 1.0:
            raise FetchError(f"finger_span must be above 0 and at most 1, got {reprlib.repr(self.finger_span)}")
        _whole("act_steps", self.act_steps, 1, self.chunk)
        if not _number(self.ensemble_decay) or abs(self.ensemble_decay) > MAX_ENSEMBLE_DECAY:
            raise FetchError(f"ensemble_decay must be a number from {-MAX_ENSEMBLE_DECAY:.2f} to "
                             f"{MAX_ENSEMBLE_DECAY:.2f}, got {reprlib.repr(self.ensemble_decay)}")

    @classmethod
    def of(cls, kind_name: str, **settings: Any) -> PolicySettings:
        """A policy of `kind_name` with its kind's defaults, then `settings`."""
        chosen = {**kind(kind_name).defaults, **settings}
        chunk = chosen.get("chunk", cls.chunk)
        if "act_steps" not in settings and isinstance(chunk, int) and chunk >= 1:  # a shorter chunk than the default
            chosen["act_steps"] = min(chosen.get("act_steps", cls.act_steps), chunk)  # covers fewer steps
        return cls(kind=kind_name, **chosen)

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class PolicyConfig(PolicySettings):
    """A policy's settings and the size of its input: all a network is built from."""

    obs_size: int = dataclasses.field(default=0, kw_only=True)
    image_size: int = dataclasses.field(default=0, kw_only=True)
    """[px] the side of the square camera images a pixel policy sees (0: it sees none)."""
    image_quality: str = dataclasses.field(default="", kw_only=True)
    """how those images are drawn (`rendering.IMAGE_QUALITIES`; "": it sees none)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        _whole("obs_size", self.obs_size, 1, MAX_INPUTS)
        size = self.image_size
        if not isinstance(size, int) or isinstance(size, bool) or not 0 <= size <= MAX_IMAGE_SIZE \
                or bool(self.cameras) != (size > 0):
            raise FetchError(f"policy image_size must be the images' side in pixels, 1 to {MAX_IMAGE_SIZE} (0 without "
                             f"cameras), got {reprlib.repr(size)}")
        if not isinstance(self.image_quality, str) \
                or self.image_quality not in (IMAGE_QUALITIES if self.cameras else ("",)):
            raise FetchError(f"policy image_quality must be one of {', '.join(IMAGE_QUALITIES)} with cameras, \"\" "
                             f"without, got {reprlib.repr(self.image_quality)}")
        if not all(i < self.obs_size for i in self.blind):
            raise FetchError(f"blind must list input entries 0..{self.obs_size - 1}, got {reprlib.repr(self.blind)}")

    @staticmethod
    def upgraded(raw: Mapping[str, Any]) -> dict[str, Any]:
        """A checkpoint's policy settings as they are now: a pixel policy saved before the image quality was
        recorded learnt from "full" images (the only kind there was), a policy saved before
        `finger_scale` learnt the fingers' action as recorded, one saved before `finger_span` spanned 1, and one
        saved before `act_steps` predicted every step."""
        raw = {"finger_scale": 0.0, "finger_span": 1.0, "act_steps": 1, **raw}
        if "image_quality" in raw:
            return raw
        return {**raw, "image_quality": "full" if raw.get("cameras") else ""}

    @classmethod
    def from_dict(cls, raw: dict[str, Any]) -> PolicyConfig:
        raw = cls.upgraded(raw)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(raw) - known
        if unknown:
            raise FetchError(f"unknown policy settings {reprlib.repr(sorted(map(str, unknown)))}; known: "
                             f"{sorted(known)}")
        if "kind" not in raw:
            raise FetchError(f"the policy settings name no kind; known: {', '.join(POLICY_KINDS)}")
        return cls(**raw)

    @property
    def settings(self) -> PolicySettings:
        """These settings without the input size."""
        raw = self.as_dict()
        del raw["obs_size"], raw["image_size"], raw["image_quality"]
        return PolicySettings(**raw)
