"""One generation attempt: for each subtask pick a source segment, carry it over to the object's
new pose, blend it in from where the hand is, execute it through the env, and keep the result if
the task succeeded."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

from fetch.dataset.episode import Demo, EpisodeBuffer
from fetch.dataset.formats import recorded_layout
from fetch.dataset.habits import SQUEEZE
from fetch.dataset.render.frames import StateRenderer
from fetch.errors import FetchError, UnknownNameError
from fetch.experts.base import Expert
from fetch.generate.room import STARTS, finger_room, pass_over, tight_start
from fetch.generate.segments import Segment, annotate, from_frame, held_grip, to_frame
from fetch.rendering import DEFAULT_IMAGE_QUALITY
from fetch.robot import ACTION_STEP, HAND_RESPONSE, dart_std
from fetch.tasks import MAX_STEPS
from fetch.tasks.subtasks import Frame, Grasped, Lifted, Scene

SELECTIONS = ("nearest", "random")
"""How a source segment is chosen for each subtask: among the `nearest_k` whose hand started
closest to where the hand is now (in the subtask's frame), or uniformly."""


@dataclasses.dataclass(frozen=True)
class Options:
    """How attempts are made (every field is recorded in the dataset and must match on resume)."""

    max_steps: int | None = None
    """steps per attempt at most (None: `generate` gives the task's registered horizon, or more where
    the source demos need it: `Sources.attempt_steps`)."""
    success_hold_steps: int = 5
    """an attempt succeeds if `is_success` holds over its last this many steps (with `stop_on_success`: once
    it has held this long, and stops there)."""
    stop_on_success: bool = False
    """end an attempt once it has succeeded (MimicGen's demos end there). By default every attempt runs to
    `max_steps`, the last source segment to its source demo's end and then holding still, as the
    collector's expert demos do: a policy trained on demos that stop at success never sees what to do after
    it, and undoes it (Bin-place-v2: 4 % success from 1000 such demos, the object placed and then lost)."""
    selection: str = "nearest"
    nearest_k: int = 3
    noise: float = 0.1
    """standard deviation of Gaussian noise added to the executed arm action a[:3], in action units (0.1: 5 mm of
    hand target), the clean action being recorded as `expert_actions` (DART; what training learns). MimicGen
    adds 0.05 and trains on the noisy actions; that cut a policy trained on the result from 94 % to 74 %
    (PickPlace-v2, docs/generate.md)."""
    finger_noise: float | None = None
    """standard deviation of the noise on a[3], whose unit is a metre of finger target (a finger travels 5 cm);
    None: `noise`. So 0.1 moves the finger target by 10 cm and the fingers swing between open and closed from
    step to step; `noise * ACTION_STEP` (0.005), as many metres as the hand's, kept 97 % of Bin-place's attempts
    against 87 %, but its pixel policy did worse (80 against 89 %; docs/generate.md), so it is not the default."""
    transit_speed: float = 0.8
    """the blend-in moves the hand at most this fraction of full speed on top of the segment's motion."""
    retries: int = 1
    """how many times an attempt may make a missed or lost grasp again (the fingers closed beside the
    block or on its top edge, the block slipped: not held at the end of the segment after the grasp),
    from where the hand is, with a newly chosen grasp segment. The kept demo then shows a
    recovery (open, come back, grasp), which a policy otherwise never sees (docs/generate.md)."""
    fit_opening: bool = True
    """open the fingers, coming down on an object nothing has touched yet, no wider than puts each midway
    between the object and whatever stands beside it (a bin's wall: `finger_room`), rather than as wide
    as the source opened them; where nothing is near, as the source did."""
    steady_fit: bool = True
    """where `fit_opening` narrowed an approach, the noise on the fingers during it is the hand's metres
    (`noise * ACTION_STEP`): at `finger_noise`'s 0.1 they swing fully open and shut whatever opening is asked
    for, a finger lands on the wall and the source's squeeze, replayed on time, closes 4 cm above the object
    (38 % of Bin-place's demos that start beside the bin, against 9 % steadied; docs/generate.md)."""
    starts: str = "all"
    """`STARTS`: "tight" makes attempts only from the starts where the first object stands close beside
    something (a bin's wall), skipping the others, for a second dataset of those rare starts to train on
    beside the first (docs/generate.md, "Starts beside a wall")."""
    blend_fraction: float = 0.75
    """the offset is blended out over this fraction of the steps before the segment's closest
    approach to its reference (so the grasp or placement itself is replayed exactly)."""
    hand_response: float | None = None
    """the share of a commanded step the hand is taken to cover: each step commands the hand's distance to the
    carried-over path divided by this. None: the task's (`HAND_RESPONSES`, else 1). At 1 the hand, which covers
    `HAND_RESPONSE` (0.64) of it, trails a moving path by about half a step's motion, 1-1.5 cm on an approach; at
    `HAND_RESPONSE` it follows the path (docs/generate.md, "Following the path")."""

    def __post_init__(self) -> None:
        if self.selection not in SELECTIONS:
            raise UnknownNameError("selection", self.selection, SELECTIONS)
        if self.starts not in STARTS:
            raise UnknownNameError("starts", self.starts, STARTS)
        for name, value, low in (("max_steps", self.max_steps, 1), ("success_hold_steps", self.success_hold_steps, 1),
                                 ("nearest_k", self.nearest_k, 1), ("retries", self.retries, 0)):
            if value is not None and value < low:
                raise FetchError(f"--{name.replace('_', '-')} must be at least {low}, got {value}")
        if self.max_steps is not None and self.max_steps > MAX_STEPS:
            raise FetchError(f"--max-steps must be at most {MAX_STEPS}, got {self.max_steps}")
        for flag, std in (("noise", self.noise), ("finger-noise", self.finger_noise)):
            if std is not None and not (math.isfinite(std) and std >= 0):
                raise FetchError(f"--{flag} must be a finite standard deviation >= 0, got {std}")
        if not 0 < self.transit_speed <= 1 or not 0 <= self.blend_fraction <= 1:
            raise FetchError("transit_speed must be in (0, 1] and blend_fraction in [0, 1]")
        if self.hand_response is not None and not (
                isinstance(self.hand_response, int | float) and 0.1 <= self.hand_response <= 1):
            raise FetchError(f"--hand-response must be a number from 0.1 to 1 (the hand covers {HAND_RESPONSE} of a "
                             f"commanded step), got {self.hand_response}")

    @property
    def finger_std(self) -> float:
        """[a[3] units: m of finger target] the std of the noise on the fingers."""
        return float(dart_std(self.noise, self.finger_noise)[3])


HAND_RESPONSES: dict[str, float] = {"Drawer-close-v2": HAND_RESPONSE}
"""The tasks on which generate follows the path unless told otherwise (`Options.hand_response`). Drawer-close's
demos bring the fingers down into a slot behind the handle only 1.3 cm wider than they are: trailing the path, 40 %
of the demos made from a pad operator's came down on the drawer's front instead and dragged it shut, and camera
policies trained on them got 72-97 % over three training seeds (docs/results/path_following.md). Elsewhere 1 is
kept until the missions are measured with it: it kept a few points more of the attempts."""


def task_hand_response(env_id: str) -> float:
    """`Options.hand_response` on `env_id` unless told: its `HAND_RESPONSES` entry, else 1."""
    return HAND_RESPONSES.get(env_id, 1.0)


class Result(NamedTuple):
    """What one attempt gave: a demo if it succeeded, and which source segments it used."""

    number: int
    seed: int
    success: bool
    steps: int
    choices: tuple[tuple[str, int, int, int], ...]
    """per segment executed, in order: (source demo, first step, end step, subtask index); a subtask made
    again (`Options.retries`) appears again."""
    starts: tuple[int, ...]
    """per segment executed, the attempt's step at which it began (`states[start]` is the state it began from)."""
    demo: Demo | None
    images: dict[str, np.ndarray]
    """per camera asked for, the (T + 1, size, size, 3) uint8 images of the demo's `states` (rendered
    where the attempt was made; `obs/` holds all but the last, `next_obs/` all but the first); none
    for a failed attempt."""
    made: bool = True
    """False: its start was skipped (`Options.starts`), no attempt was made from it."""


class Plan(NamedTuple):
    """A segment carried over to a new episode (`Generator.plan`)."""

    path: np.ndarray
    """(N, 3) [m] the hand's targets."""
    grips: np.ndarray
    """(N,) the source's finger commands."""
    openings: np.ndarray | None
    """(N,) [m] the finger openings they led to in the source (narrowed where `fitted`), or None."""
    fitted: bool = False
    """the openings were narrowed to the room beside the object (`Options.fit_opening`)."""


def rng_for(seed: int, number: int) -> np.random.Generator:
    """The random stream of attempt `number` (segment choices, noise): the same in any process."""
    return np.random.default_rng([seed, number])


class Generator:
    """Makes attempts in one env from a fixed set of source segments (`sources[d][k]`: demo d's
    segment of subtask k). With `cameras`, a successful attempt's images are rendered from its states at
    `image_size` [px] and `image_quality`, as `collect --cameras` and `render-obs` render them (`StateRenderer`)."""

    def __init__(self, env_id: str, env_kwargs: dict[str, Any], sources: Sequence[Sequence[Segment]],
                 options: Options, seed: int, cameras: tuple[str, ...] = (), image_size: int = 0,
                 image_quality: str = DEFAULT_IMAGE_QUALITY) -> None:
        if options.max_steps is None:
            raise FetchError("Options.max_steps must be set before attempts are made (generate sets it)")
        self.max_steps: int = options.max_steps
        self.env = gym.make(env_id, max_episode_steps=options.max_steps, **env_kwargs)
        base: Any = self.env.unwrapped
        self.base = base
        self.env_id = env_id
        self.subtasks = type(base.task).subtasks
        if not sources:
            raise FetchError("no source demo could be cut into subtasks; nothing to generate from")
        self.sources = sources
        self.options = options
        self._noise_std = dart_std(options.noise, options.finger_noise)
        response = options.hand_response if options.hand_response is not None else task_hand_response(env_id)
        self.hand_step = ACTION_STEP * response
        """[m] how far the hand is taken to move per step at |a| = 1 (`Options.hand_response`)."""
        self._steady_std = dart_std(options.noise, min(options.finger_std, options.noise * ACTION_STEP))
        self.seed = seed
        self.env_kwargs, self.cameras, self.image_size = env_kwargs, cameras, image_size
        self.image_quality = image_quality
        self._renderer: StateRenderer | None = None  # made at the first success that needs images
        self.scene = Scene(base.model)
        self.buffer = EpisodeBuffer(recorded_layout(self.env), capacity=self.max_steps)
        self._obs: dict[str, np.ndarray] = {}  # the env's latest observation
        self._start_in_frame = [np.stack([s[k].hand_in_frame() for s in sources]) for k in range(len(self.subtasks))]
        # Only the first part approaches an object that nothing has touched yet (`pass_over`).
        self._loose = [self.scene.loose(s.reference) if k == 0 and s.done is not None else None
                       for k, s in enumerate(self.subtasks)]
        self._loose_body = [int(base.model.site_bodyid[self.scene.site(s.reference)]) if loose else -1
                            for s, loose in zip(self.subtasks, self._loose, strict=True)]
        # Per subtask whose signal holds an object (`Grasped`, `Lifted`): (its index, the object's body, the
        # first subtask that grasps that body, which a retry makes again).
        grasps: dict[str, int] = {}
        self._holds = [(j, s.done.body, grasps.setdefault(s.done.body, j)) for j, s in enumerate(self.subtasks)
                       if isinstance(s.done, (Grasped, Lifted))]

    def choose(self, k: int, frame: Frame, held: np.ndarray, rng: np.random.Generator) -> Segment:
        """The source segment for subtask `k`, the hand being at `held` [m] and its frame at `frame`."""
        n = len(self.sources)
        if self.options.selection == "random":
            return self.sources[int(rng.integers(n))][k]
        distance = np.linalg.norm(self._start_in_frame[k] - to_frame(frame, held), axis=1)
        nearest = np.argsort(distance, kind="stable")[: self.options.nearest_k]
        return self.sources[int(nearest[int(rng.integers(len(nearest)))])][k]

    def plan(self, segment: Segment, frame: Frame, held: np.ndarray, loose: tuple[float, float] | None = None,
             body: int = -1) -> Plan:
        """The segment carried over to `frame` (its targets, finger commands and openings: `Plan`), with the
        hand's offset from its start blended out (MimicGen interpolates first; we spread the offset
        over the segment's approach, and prepend steps only when that would be too fast). `loose`:
        the extent (radius, height [m]) of the loose object at the frame's origin that the segment
        approaches untouched (`pass_over`), and `body` its body: the fingers open no wider than leaves
        room beside it (`finger_room`), where `Options.fit_opening`."""
        o = self.options
        moved = from_frame(frame, to_frame(segment.frame, segment.targets))
        shift = np.zeros(3)
        if segment.settle is not None:  # close the source's last gap to the goal
            shift += from_frame(frame, to_frame(segment.frame, segment.frame.pos + segment.settle)) - frame.pos
        if segment.goal is not None:  # end where the attempt's goal is, not where the source's would be
            shift += self._obs["desired_goal"] - from_frame(frame, segment.goal)
        if shift.any():
            by = segment.closest if segment.settle_by is None else segment.settle_by
            ramp = np.clip(np.arange(1, segment.length + 1) / (by + 1), 0.0, 1.0)
            moved = moved + ramp[:, None] * shift
        start = from_frame(frame, to_frame(segment.frame, segment.held))
        offset = held - start
        n_blend = int(o.blend_fraction * segment.closest)
        n_needed = math.ceil(float(np.abs(offset).max()) / (o.transit_speed * self.hand_step) - 1e-9)
        n_pre = max(0, n_needed - n_blend)
        span = n_pre + n_blend
        weights = np.clip(1.0 - np.arange(1, n_pre + segment.length + 1) / span, 0.0, 1.0) if span else \
            np.zeros(n_pre + segment.length)
        path = np.concatenate([np.repeat(start[None], n_pre, axis=0), moved]) + weights[:, None] * offset
        # Blending out a height offset can dip the path below both its ends (a segment from a goal in
        # the air carried over to one on the table): the hand would press on what is below it and the
        # labels would say so. Up to the closest approach it stays at or above the lower end.
        arrive = n_pre + segment.closest
        floor = min(held[2], path[arrive, 2])
        path[:arrive, 2] = np.maximum(path[:arrive, 2], floor)
        if loose is not None:
            pass_over(path, frame.pos, *loose)
        grips = np.concatenate([np.full(n_pre, segment.grips[0]), segment.grips])
        openings = None if segment.openings is None else \
            np.concatenate([np.full(n_pre, segment.openings[0]), segment.openings])
        if o.fit_opening and loose is not None and body >= 0 and openings is not None:
            room = finger_room(self.base.model, self.base.data, self.scene.fingers, body, frame.pos, path[arrive],
                               self._opening(), float(openings.max()))
            if room is not None:
                return Plan(path, grips, np.minimum(openings, room), fitted=True)
        return Plan(path, grips, openings)

    def _opening(self) -> float:
        """[m] the fingers' opening now."""
        return float(self._obs["observation"][self.base.observation_layout["gripper_state"]].mean())

    def tight(self) -> bool:
        """Whether the env, as it has just been reset, starts tight (`room.tight_start`)."""
        return tight_start(self.base, self.scene, self._opening())

    def attempt(self, number: int) -> Result:
        """Attempt `number`: reset with seed + number, execute one segment per subtask. Where a grasp was
        missed or lost (`lost`: the object not held on the last two steps of a later segment but the last),
        the attempt makes the grasp again from where the hand is, up to `Options.retries` times."""
        o, env, base, buf = self.options, self.env, self.base, self.buffer
        seed = self.seed + number
        rng = rng_for(self.seed, number)
        obs, info = env.reset(seed=seed)
        self._obs = obs
        if o.starts == "tight" and not self.tight():
            return Result(number, seed, False, 0, (), (), None, {}, made=False)
        buf.begin(obs, base.get_state())
        started = time.time()
        held_for, steps, grip, opening = 0, 0, 0.0, None
        choices: list[tuple[str, int, int, int]] = []
        starts: list[int] = []
        success = False
        target = held_grip(base)
        k, retries = 0, 0
        while k < len(self.subtasks) and steps < self.max_steps and not (success and o.stop_on_success):
            subtask = self.subtasks[k]
            held = held_grip(base)
            frame = subtask.frame(self.scene, base.data)
            segment = self.choose(k, frame, held, rng)
            choices.append((segment.demo, segment.start, segment.end, k))
            starts.append(steps)
            path, grips, openings, fitted = self.plan(segment, frame, held, self._loose[k], self._loose_body[k])
            steady = fitted and o.steady_fit
            # Judged at the end of a segment after the grasp that is not the last (the lift): a good grasp may
            # close only during it (the hand arrived late), and the last segment lets go by design.
            check = len(path) if retries < o.retries and 0 < k < len(self.subtasks) - 1 else 0
            again = None
            for i, (target, grip) in enumerate(zip(path, grips, strict=True)):
                opening = None if openings is None else float(openings[i])
                success, held_for = self._step(target, grip, opening, rng, held_for, steady)
                steps += 1
                if check and i + 1 >= check - 1:  # not held on two steps running: a finger's contact flickers
                    lost = self.lost(k)
                    if lost is None or i + 1 == check:
                        again, check = lost, 0
                    if again is not None:
                        break
                if steps >= self.max_steps or (success and o.stop_on_success):
                    break
            k, retries = (k + 1, retries) if again is None else (again, retries + 1)
        if o.stop_on_success:
            # The source's last segment ends when its success had held; give ours a few steps more.
            extra = 2 * o.success_hold_steps
            while not success and steps < self.max_steps and extra > 0:
                success, held_for = self._step(target, grip, opening, rng, held_for)
                steps += 1
                extra -= 1
        else:  # to the horizon, holding the last target; judged by the last steps
            while steps < self.max_steps:
                success, held_for = self._step(target, grip, opening, rng, held_for)
                steps += 1
        demo = None
        if success:
            demo = buf.demo({"seed": seed, "success": True, "env_id": self.env_id, "device": "generate",
                             "attempt": number, "control_hz": 0.0, "achieved_hz": 0.0, "started": started,
                             "ended": time.time()})
            labels = annotate(base, self.subtasks, demo.arrays["states"], demo.arrays["actions"][:, 3]).labels
            demo.arrays["subtasks"] = labels
        images = self.render(demo.arrays["states"], seed) if demo is not None else {}
        return Result(number, seed, success, steps, tuple(choices), tuple(starts), demo, images)

    def lost(self, k: int) -> int | None:
        """While subtask `k` runs: the grasp subtask to make again if an object grasped before `k` (an earlier
        subtask's signal is `Grasped` or `Lifted` of it) is not held now; else None."""
        for j, body, grasp in self._holds:
            if j < k and not Grasped(body)(self.scene, self.base.data):
                return grasp
        return None

    def render(self, states: np.ndarray, seed: int) -> dict[str, np.ndarray]:
        """Each camera's (N, size, size, 3) images of N saved states of the attempt reset with `seed` (its
        looks, where the env draws them); a separate env's, so the attempts' own env is never restored."""
        if not self.cameras:
            return {}
        if self._renderer is None:
            self._renderer = StateRenderer(self.env_id, self.env_kwargs, self.image_size, self.image_size,
                                           self.image_quality)
        return {camera: self._renderer.frames(states, camera, seed) for camera in self.cameras}

    def _step(self, target: np.ndarray, grip: float, opening: float | None, rng: np.random.Generator,
              held_for: int, steady: bool = False) -> tuple[bool, int]:
        """One step towards `target` with DART's noise (`steady`: on the fingers only the hand's metres)."""
        base, buf = self.base, self.buffer
        move = (target - held_grip(base)) / self.hand_step
        clean = np.append(np.clip(move, -1.0, 1.0), self._fingers(grip, opening)).astype(np.float32)
        action, label = clean, None
        if self._noise_std.any():  # DART: execute a perturbed action, label the clean one (`expert_actions`)
            noise = rng.normal(0.0, 1.0, 4) * (self._steady_std if steady else self._noise_std)
            action = clean.copy()
            action[:3] = np.clip(move + noise[:3], -1.0, 1.0)
            action[3] = np.clip(clean[3] + noise[3], -1.0, 1.0)
            label = clean
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._obs = obs
        base.get_state(out=buf.state_row())
        ok = info["is_success"] >= 1.0
        buf.record(base.last_action, obs, float(reward), terminated, truncated, ok, time.time(), label)
        held_for = held_for + 1 if ok else 0
        return held_for >= self.options.success_hold_steps, held_for

    def _fingers(self, grip: float, opening: float | None) -> float:
        """The clean a[3]. A squeeze (the source closing on or holding something) as the source gave it;
        otherwise the expert's finger servo towards the opening the source's command led to, so that a
        finger the noise moved is brought back and the label says how (replaying the source's own
        commands, the fingers of a policy trained on the result drifted open and never grasped:
        Box-close-v2, 1 % success from 1000 demos)."""
        if opening is None or grip <= SQUEEZE:
            return float(np.clip(grip, -1.0, 1.0))
        return Expert.finger_servo(self._obs, self.base.observation_layout, opening)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self.env.close()
