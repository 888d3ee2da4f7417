"""Training data from a dataset: per-demo observation and action arrays, the split, normalisation."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fetch.dataset.habits import (
    HORIZON_MARGIN,
    first_success,
    layout_of,
    observation_changes,
    pose_columns,
    still_steps,
)
from fetch.errors import DatasetError
from fetch.tasks import registered_horizon

OBS_KEYS = ("observation", "desired_goal")
"""What a policy sees, concatenated in this order: the state and the goal (achieved_goal repeats
the object's position, which `observation` already holds)."""

GRIP = slice(0, 3)
"""Where the grip site's position is in every task's observation: first (tests/test_envs.py holds it)."""
PROPRIOCEPTION = ("grip_pos", "gripper_state", "grip_velp", "gripper_vel")
"""The parts of every task's observation a real Fetch knows about itself: where its hand is and how fast
it moves, how far its fingers are open and how fast they move. A pixel policy sees these, the goal and
the camera images, and nothing else of the state."""


def flat_obs(obs: Mapping[str, np.ndarray], goal_offsets: bool = False, blind: Sequence[int] = ()) -> np.ndarray:
    """The policy's input from an observation dict: (..., D) float32, batched or not; with
    `goal_offsets`, the goal relative to the achieved goal and to the grip site too (D + 6); the
    entries `blind` set to 0."""
    x = np.concatenate([np.asarray(obs[k], np.float32) for k in OBS_KEYS], axis=-1)
    x = with_goal_offsets(x, np.asarray(obs["achieved_goal"], np.float32)) if goal_offsets else x
    return _blinded(x, blind)


def _blinded(x: np.ndarray, blind: Sequence[int]) -> np.ndarray:
    if not len(blind):
        return x
    x = x.copy()
    x[..., list(blind)] = 0.0
    return x


def velocity_columns(layout: Mapping[str, slice]) -> tuple[int, ...]:
    """The entries of the policy's input that are velocities (the observation's parts named `*vel*`).

    A policy that sees how fast the hand and the object move can learn to go on doing what it did a
    moment ago: from demos with an uneven pace (a person's, who slows down, stops and starts again) it
    learns "slow goes on slow" and creeps to a stop (the copycat problem of behaviour cloning from
    observation histories). Left out (`--no-velocities`), it acts on where things are."""
    return tuple(i for name, part in layout.items() if "vel" in name for i in range(part.start, part.stop))


def unseen_by_pixels(layout: Mapping[str, slice] | None, goal_offsets: bool) -> tuple[int, ...]:
    """The entries of the policy's input (`flat_obs`) a pixel policy does not see: every part of the
    observation but `PROPRIOCEPTION` and, with goal offsets, the goal relative to the achieved goal (the
    object's position in disguise). It sees the goal, and the goal relative to its hand."""
    if not layout or any(name not in layout for name in PROPRIOCEPTION):
        raise DatasetError(f"a pixel policy needs the observation's layout with {', '.join(PROPRIOCEPTION)}; "
                           f"this task's is {sorted(layout or {})}")
    size = max(part.stop for part in layout.values())
    seen = {i for name in PROPRIOCEPTION for i in range(layout[name].start, layout[name].stop)}
    unseen = [i for i in range(size) if i not in seen]
    if goal_offsets:
        unseen += list(range(size + 3, size + 6))  # desired - achieved
    return tuple(unseen)


def with_goal_offsets(x: np.ndarray, achieved: np.ndarray) -> np.ndarray:
    """`x` (the observation, then the desired goal) followed by desired - achieved and desired - grip.

    An MLP could compute these differences itself, but from inputs normalised one by one it learns
    them slowly: on Push they raised one network's success from 71 to 75 % (500 evaluation episodes,
    3 training seeds; docs/results/learning_curves.md)."""
    desired = x[..., -3:]
    return np.concatenate([x, desired - achieved, desired - x[..., GRIP]], axis=-1)


@dataclasses.dataclass(frozen=True)
class Episode:
    """One demo: T observations (before each step) and the T actions to learn from them (the
    demo's `expert_actions` where it has them, else `actions`)."""

    name: str
    seed: int
    obs: np.ndarray
    """(T, D) `flat_obs` of each step."""
    actions: np.ndarray
    achieved: np.ndarray
    """(T, 3) the achieved goal of each step (for `policy_inputs` with goal offsets)."""
    first_success: int | None = None
    """[steps] how long the demo took to succeed, as recorded (None: it never did, or this is a stretch a
    person drove)."""
    corrected: bool = False
    """A stretch of an attempt that a person took over from a policy (`--device takeover`)."""
    images: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)
    """camera -> (T, H, W, 3) uint8: its image at each step, where the demos were loaded with images."""


def policy_inputs(episode: Episode, goal_offsets: bool, blind: Sequence[int] = ()) -> np.ndarray:
    """What a policy with (or without) goal offsets, and not seeing the entries `blind`, sees at each
    step of `episode`."""
    return _blinded(with_goal_offsets(episode.obs, episode.achieved) if goal_offsets else episode.obs, blind)


@dataclasses.dataclass(frozen=True)
class Demos:
    """The demos a policy learns from, split as the dataset's masks say."""

    origin: str
    """Where the demos came from (the dataset file), as a run records it."""
    env_id: str
    env_kwargs: dict[str, object]
    train: tuple[Episode, ...]
    valid: tuple[Episode, ...]
    seeds: frozenset[int]
    """Every reset seed in the dataset (all demos, kept failures too): evaluation avoids them."""
    origins: tuple[str, ...] = ()
    """Every dataset file the demos came from, where they came from several (`load_many`)."""
    cameras: tuple[str, ...] = ()
    """The cameras whose images every demo holds (`Episode.images` where loaded with images)."""
    image_size: int = 0
    """[px] their side."""
    image_quality: str = ""
    """how they are drawn (`rendering.IMAGE_QUALITIES`)."""

    @property
    def horizon(self) -> int:
        """[steps] the episode length a policy learnt from these demos is given (`needed_horizon`)."""
        return needed_horizon(self.env_id, self.train)


def needed_horizon(env_id: str, episodes: Sequence[Episode]) -> int:
    """[steps] the registered horizon, or more where the demos need it: `HORIZON_MARGIN` times the 95th
    percentile of the steps they took to succeed. People are slower than the task's 50 steps; a policy
    that learnt from them is judged on the time they took (and, by `eval`, on the 50 steps too)."""
    took = [e.first_success for e in episodes if e.first_success is not None]
    needed = math.ceil(HORIZON_MARGIN * float(np.percentile(took, 95))) if took else 0
    return max(registered_horizon(env_id), needed)


def load_demos(path: str | os.PathLike[str], images: bool = False) -> Demos:
    """The successful demos of a dataset (file or collector directory): `mask/train` to learn from and
    `mask/valid` to validate on; of attempts a person corrected (`--device takeover`), the stretches the
    person drove, failed attempts' too. With `images`, each demo's camera images too (for a pixel
    policy; they take memory: 12 kB per step and camera at 64 x 64, 21 kB at 84 x 84). The file is checked
    as every tool checks it (`require_valid`) in the same pass that reads the demos: each demo file is
    opened once."""
    from fetch.dataset import open_dataset
    from fetch.dataset.schema import image_key
    from fetch.dataset.validation import require_valid

    with open_dataset(path) as ds:
        masks = ds.masks()
        for split in ("train", "valid"):
            if split not in masks:
                raise DatasetError(f"{ds.path} has no mask/{split}; make one with `gym-fetch split {path}`")
        cameras = ds.layout.cameras if images else ()
        wanted = {f"obs/{image_key(c)}" for c in cameras}  # images are most of a demo's bytes: only these are read
        learnt = set(masks["train"]) | set(masks["valid"]) | set(masks.get("failed", []))
        layout = layout_of(ds.env_id)
        seeds: set[int] = set()
        episodes: dict[str, tuple[Episode, ...]] = {}

        def visit(name: str, attrs: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
            seeds.add(int(attrs["seed"]))
            # A failed attempt that a person corrected still holds what they did where they drove.
            if name in learnt and (bool(attrs["success"]) or "intervention" in arrays):
                episodes[name] = _episodes(name, attrs, arrays, layout, cameras)

        require_valid(ds, keep=wanted.__contains__, visit=visit)
        corrected = [n for n in masks.get("failed", []) if n in episodes]
        train = tuple(e for n in [*masks["train"], *corrected] for e in episodes[n])
        valid = tuple(e for n in masks["valid"] for e in episodes[n])
        env_id, env_kwargs = ds.env_id, dict(ds.env_kwargs)
        where = ds.path.resolve()
        image_size = ds.layout.image_size if cameras else 0
        quality = ds.layout.image_quality if cameras else ""
    if not train:
        raise DatasetError(f"{where}: mask/train lists no demo with a step; a policy needs at least one")
    return Demos(str(where), env_id, env_kwargs, train, valid, frozenset(seeds), cameras=cameras,
                 image_size=image_size, image_quality=quality)


def load_many(paths: Sequence[str | os.PathLike[str]], correction_weight: int = 1, images: bool = False) -> Demos:
    """The demos of several datasets of one task, as one (`gym-fetch train D1 D2 ...`): the original demos
    and the attempts a person corrected (`--device takeover`). Each training stretch a person drove is
    repeated `correction_weight` times (corrections are few beside the demos they correct). With
    `images`, the cameras all of them hold, at one size."""
    if correction_weight < 1:
        raise DatasetError(f"--correction-weight must be a whole number >= 1, got {correction_weight}")
    loaded = [load_demos(p, images) for p in paths]
    first = loaded[0]
    for other in loaded[1:]:
        if (other.env_id, other.env_kwargs) != (first.env_id, first.env_kwargs):
            raise DatasetError(f"{other.origin} holds {other.env_id} {other.env_kwargs} demos and {first.origin} "
                               f"{first.env_id} {first.env_kwargs}: a policy learns one task; train on datasets "
                               "of the same task and settings")
        if images and other.cameras and first.cameras and ((other.image_size, other.image_quality)
                                                             != (first.image_size, first.image_quality)):
            raise DatasetError(f"{other.origin} holds {other.image_size} px {other.image_quality}-quality images and "
                               f"{first.origin} {first.image_size} px {first.image_quality}: a pixel policy learns "
                               "from images of one size and quality")
    cameras = tuple(c for c in first.cameras if all(c in d.cameras for d in loaded))
    train = tuple(e for d in loaded for e in d.train for _ in range(correction_weight if e.corrected else 1))
    return Demos(first.origin if len(loaded) == 1 else " + ".join(d.origin for d in loaded), first.env_id,
                 first.env_kwargs, train, tuple(e for d in loaded for e in d.valid),
                 frozenset().union(*(d.seeds for d in loaded)), tuple(d.origin for d in loaded),
                 cameras, first.image_size if cameras else 0, first.image_quality if cameras else "")


def with_reflections(demos: Demos) -> Demos:
    """`demos` with each training demo's mirror image added (`gym-fetch train --mirror`): the demo
    reflected in the vertical plane through the start's grip site, which on a symmetric task
    (`fetch.env.FetchEnv.reflection`) is another demo of it, the expert's actions reflected too.
    Validation stays as recorded."""
    import gymnasium as gym

    kwargs: dict[str, Any] = dict(demos.env_kwargs)
    env = gym.make(demos.env_id, **kwargs)
    try:
        reflection = env.unwrapped.reflection()  # type: ignore[attr-defined]
    finally:
        env.close()
    size = reflection.observation.order.shape[0]
    sign = reflection.action_sign.astype(np.float32)

    def reflect(e: Episode) -> Episode:
        obs = np.concatenate([reflection.observation(e.obs[:, :size]), reflection.goal(e.obs[:, size:])], axis=1)
        return Episode(f"{e.name} (mirrored)", e.seed, obs.astype(np.float32), e.actions * sign,
                       reflection.goal(e.achieved).astype(np.float32), e.first_success, e.corrected)

    return dataclasses.replace(demos, train=demos.train + tuple(reflect(e) for e in demos.train))


def learnt_actions(actions: np.ndarray, finger_scale: float, span: float = 1.0) -> np.ndarray:
    """(..., 4) actions as a policy learns them: a[3] companded, |a[3]| <= `finger_scale` stretched over
    [-span, span] and the rest of [-1, 1] squeezed into what is left up to +-2 span, so that the fingers'
    servo (a few hundredths: open to 3 cm, hold at 5) is resolved as finely as the hand's moves and the
    squeeze (-1) stays apart from it; `finger_scale` 0: as they are. `acted_actions` is the inverse."""
    if not finger_scale:
        return actions
    out = np.array(actions, np.float32)
    a = out[..., 3]
    size = np.abs(a)
    out[..., 3] = span * np.where(size <= finger_scale, a / finger_scale,
                                  np.sign(a) * (1.0 + (size - finger_scale) / (1.0 - finger_scale)))
    return out


def acted_actions(learnt: np.ndarray, finger_scale: float, span: float = 1.0) -> np.ndarray:
    """The actions a policy's (..., 4) outputs in `learnt_actions`' space stand for."""
    if not finger_scale:
        return learnt
    out = np.array(learnt, np.float32)
    y = out[..., 3] / span
    size = np.abs(y)
    out[..., 3] = np.where(size <= 1.0, y * finger_scale,
                           np.sign(y) * (finger_scale + (size - 1.0) * (1.0 - finger_scale)))
    return out


def learnt_steps(arrays: Mapping[str, np.ndarray], layout: Mapping[str, slice] | None = None) -> np.ndarray:
    """(T,) bool: the steps of a demo a policy learns from: all but those that change nothing before the
    task is done (`habits.still_steps`: a person's pauses, the hand resting on a grasp already made).
    In such a step the scene looks as in the one before and the action says "stay", so a policy that
    learns it rests there for good (docs/operators.md). Once the task is done, staying still is what
    the demo teaches, and is kept. `layout`: the observation's (`habits.pose_columns`)."""
    obs = np.asarray(arrays["obs/observation"])
    columns = pose_columns(layout, obs.shape[1])
    still = still_steps(arrays["actions"], observation_changes(obs, arrays["next_obs/observation"], columns))
    done = first_success(arrays["is_success"]) or len(still)
    still[done:] = False
    return ~still


def _episodes(name: str, attrs: Mapping[str, Any], arrays: Mapping[str, np.ndarray],
              layout: Mapping[str, slice] | None, cameras: Sequence[str]) -> tuple[Episode, ...]:
    """What a policy learns from one demo (its attributes and arrays, read and checked): the
    demo's learnt steps, or, of an attempt a person corrected, each stretch they drove; none of a demo of
    no steps."""
    from fetch.dataset.reader import runs
    from fetch.dataset.schema import image_key, meant_actions

    if int(attrs["num_samples"]) == 0:
        return ()
    keep = learnt_steps(arrays, layout)
    obs = flat_obs({k: arrays[f"obs/{k}"] for k in OBS_KEYS})
    # A demo recorded under DART noise learns the expert's clean action, not the perturbed one it executed.
    actions = meant_actions(arrays)
    achieved = np.asarray(arrays["obs/achieved_goal"], np.float32)
    images = {c: arrays[f"obs/{image_key(c)}"] for c in cameras}  # the check made sure every demo has them
    if "intervention" not in arrays:
        return (Episode(name, int(attrs["seed"]), obs[keep], actions[keep], achieved[keep],
                        first_success(arrays["is_success"]), images={c: v[keep] for c, v in images.items()}),)
    # A corrected attempt teaches what the person did where they drove (HG-DAgger): each stretch is an
    # episode of its own, so no chunk of targets runs from one correction into the next.
    out = []
    for i, (a, b) in enumerate(runs(arrays["intervention"])):
        b = _let_go(arrays["actions"], a, b)
        mine = np.zeros(len(keep), bool)
        mine[a:b] = keep[a:b]
        if mine.any():
            out.append(Episode(f"{name} (takeover {i + 1})", int(attrs["seed"]), obs[mine], actions[mine],
                               achieved[mine], None, corrected=True, images={c: v[mine] for c, v in images.items()}))
    return tuple(out)


def _let_go(actions: np.ndarray, start: int, end: int) -> int:
    """The end of a stretch a person drove without its last steps of letting go: the hand held still with
    the gripper as it was, while the arm waited to go back to the policy (`takeover.HAND_BACK`). What a
    person corrected is the driving; learnt, the waiting would teach the policy to stop."""
    while end > start + 1 and not np.any(actions[end - 1, :3]) and actions[end - 1, 3] == actions[end - 2, 3]:
        end -= 1
    return end


@dataclasses.dataclass(frozen=True)
class Normalizer:
    """Per-dimension mean and std of observations; actions are already in [-1, 1] and stay so."""

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def fit(cls, episodes: Sequence[Episode], goal_offsets: bool = False, blind: Sequence[int] = ()) -> Normalizer:
        obs = np.concatenate([policy_inputs(e, goal_offsets, blind) for e in episodes]).astype(np.float64)
        # A constant dimension (e.g. a fixed goal height) keeps unit scale rather than dividing by ~0.
        std = np.maximum(obs.std(axis=0), 1e-2)
        return cls(obs.mean(axis=0).astype(np.float32), std.astype(np.float32))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return ((obs - self.mean) / self.std).astype(np.float32)


def chunk_targets(actions: np.ndarray, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """For each step t of one demo, the actions t .. t+chunk-1 (T, chunk, 4) and which of them exist
    (T, chunk) bool: past the demo's end the last action is repeated and masked out of the loss."""
    steps = len(actions)
    index = np.arange(steps)[:, None] + np.arange(chunk)[None, :]
    valid = index < steps
    return actions[np.minimum(index, steps - 1)], valid
