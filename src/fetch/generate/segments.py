"""Cutting demos into object-centric segments: per-step subtask labels from the saved states, and
each segment's hand targets, gripper commands and reference frame (what generation replays)."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterator
from typing import Any

import numpy as np

from fetch.dataset.habits import REGRIP, SQUEEZE, STILL, still_steps
from fetch.errors import FetchError
from fetch.robot import ACTION_STEP
from fetch.tasks.subtasks import Frame, Grasped, Scene, Subtask, Tracker


@dataclasses.dataclass(frozen=True)
class Segment:
    """One subtask's part of a source demo: the steps it replays, from `start` up to `end` (exclusive)."""

    demo: str
    start: int
    end: int
    held: np.ndarray
    """[m, world] where the grip site's reference was before the first step (what the step moves from)."""
    targets: np.ndarray
    """(L, 3) [m, world] each step's grip-site target: its reference plus 0.05 * a[:3]."""
    grips: np.ndarray
    """(L,) each step's a[3] (the fingers)."""
    openings: np.ndarray | None
    """(L,) [m] the fingers' mean opening after each step, what its a[3] led to (None: the task's
    observation has no fingers)."""
    frame: Frame
    """the subtask's reference frame at the segment's start."""
    closest: int
    """the step whose target comes closest to the frame's origin (the grasp, the placement)."""
    steps: np.ndarray | None = None
    """(L,) the source demo's step each replayed step ends at (None: `start` to `end`, every one)."""
    settle: np.ndarray | None = None
    """[m, world] the last segment of a task whose last segment carries its object (grasped or hooked
    before it): what would have moved the source's achieved goal onto its desired goal at its end
    (desired - achieved). A person
    stops once success shows, with the object at the edge of the success region; replayed, the
    segment closes that gap, so generated demos end with the object at the goal."""
    settle_by: int | None = None
    """the replayed step by which `settle` and `goal`'s shift are made in full (None: `closest`, the
    approach to the goal of a segment anchored there; a segment anchored on what the hand moves, a
    drawer's handle, makes them over its whole length)."""
    goal: np.ndarray | None = None
    """[m] in `frame`, the source's goal: set for a last segment that carries its object and is
    anchored on that object (a drawer's handle), not on the goal. Its start is replayed relative to
    the object (the hook stays in the slot) and its end relative to the goal: carried over, the path
    is shifted, ramping up by `settle_by`, by how far the attempt's goal is from where the source's
    would be: a drawer that the hook pulled 3 cm further open than the source's is pushed 3 cm further
    (anchored on the handle alone, it ended 3 cm short; docs/generate.md)."""

    @property
    def length(self) -> int:
        """Steps replayed (a tidied segment leaves some of `start`..`end` out)."""
        return len(self.targets)

    def hand_in_frame(self) -> np.ndarray:
        """[m] `held` in the segment's frame: what nearest-neighbour selection compares."""
        return to_frame(self.frame, self.held)


def to_frame(frame: Frame, points: np.ndarray) -> np.ndarray:
    """World points [m] expressed in `frame` (its origin, rotated by -yaw about z)."""
    c, s = math.cos(frame.yaw), math.sin(frame.yaw)
    d = np.asarray(points, np.float64) - frame.pos
    x, y = d[..., 0], d[..., 1]
    return np.stack([c * x + s * y, -s * x + c * y, d[..., 2]], axis=-1)


def from_frame(frame: Frame, points: np.ndarray) -> np.ndarray:
    """Points [m] in `frame` expressed in the world (the inverse of `to_frame`)."""
    c, s = math.cos(frame.yaw), math.sin(frame.yaw)
    p = np.asarray(points, np.float64)
    x, y = p[..., 0], p[..., 1]
    return np.stack([c * x - s * y, s * x + c * y, p[..., 2]], axis=-1) + frame.pos


def held_grip(base: Any) -> np.ndarray:
    """[m, world] the grip-site position the next action moves from: the held mocap pose less the
    fixed offset from the grip site to the mocap body (the gripper never turns)."""
    return base.data.mocap_pos[base.robot.mocap] - base.robot.grip_to_mocap


@dataclasses.dataclass(frozen=True)
class Annotation:
    """A demo cut into subtasks."""

    labels: np.ndarray
    """(T,) uint8: the subtask index of each step."""
    complete: bool
    """every subtask's signal but the last's fired (the demo has a segment for each)."""
    held: np.ndarray
    """(T + 1, 3) [m] the grip-site reference before each step (and after the last)."""
    frames: list[Frame | None]
    """per subtask, its frame at its segment's first step (None: the demo never reached it)."""

    def bounds(self) -> list[tuple[int, int]]:
        """Per subtask reached, its steps [start, end)."""
        out = []
        for k in range(int(self.labels.max()) + 1 if len(self.labels) else 0):
            steps = np.flatnonzero(self.labels == k)
            out.append((int(steps[0]), int(steps[-1]) + 1))
        return out


def annotate(base: Any, subtasks: tuple[Subtask, ...], states: np.ndarray,
             grips: np.ndarray | None = None) -> Annotation:
    """Label every step of a demo from its saved states (`states[t + 1]` is after step t), by
    restoring each in the env `base` (a FetchEnv; its state is changed). With the demo's finger
    commands `grips` (T,), a grasp that was let go and made again ends where the last one did
    (`_regrasped`): a person's first closing that touched the object did not make the grasp."""
    if not subtasks:
        raise FetchError(f"{base.task.name} declares no subtasks, so its demos cannot be segmented")
    scene = Scene(base.model)
    tracker = Tracker(subtasks, scene)
    t_total = len(states) - 1
    labels = np.zeros(t_total, np.uint8)
    held = np.zeros((t_total + 1, 3))
    frames: list[Frame | None] = [None] * len(subtasks)
    base.set_state(states[0])
    held[0] = held_grip(base)
    frames[0] = subtasks[0].frame(scene, base.data)
    for t in range(t_total):
        base.set_state(states[t + 1])
        held[t + 1] = held_grip(base)
        before = tracker.current
        labels[t] = tracker.step(base.data)
        if tracker.current != before and t + 1 < t_total:
            # The next subtask starts with step t + 1, from the state after step t.
            frames[tracker.current] = subtasks[tracker.current].frame(scene, base.data)
    squeeze = None if grips is None else np.asarray(grips) <= SQUEEZE
    for k in range(len(subtasks) - 1):
        moved = None if squeeze is None else _regrasped(base, subtasks[k], scene, states, labels, k, squeeze)
        if moved is None:
            moved = _redone(base, subtasks[k], scene, states, labels, k, held)
        if moved is not None:
            labels[np.flatnonzero(labels == k + 1)[0]:moved] = k
            base.set_state(states[moved])
            frames[k + 1] = subtasks[k + 1].frame(scene, base.data)
    return Annotation(labels, tracker.complete and frames[-1] is not None, held, frames)


def _regrasped(base: Any, subtask: Subtask, scene: Scene, states: np.ndarray, labels: np.ndarray, k: int,
               squeeze: np.ndarray) -> int | None:
    """Where subtask `k`, a grasp, really ends, if the fingers let go in the subtask after it and
    closed again (the step after which its signal holds once more); else None."""
    if not isinstance(subtask.done, Grasped):
        return None
    after = np.flatnonzero(labels == k + 1)
    if not len(after) or not squeeze[after[0] - 1] or squeeze[after].all():
        return None
    let_go = after[0] + int(np.argmin(squeeze[after]))
    closes = np.flatnonzero(squeeze[let_go:after[-1] + 1])
    if not len(closes):
        return None
    for t in range(let_go + int(closes[0]), after[-1] + 1):
        base.set_state(states[t + 1])
        if subtask.done(scene, base.data):
            return t + 1
    return None


REDONE = 0.02
"""[m] how far the hand must have gone from where a subtask's signal first held, for its coming back to
count as the subtask done again (`_redone`); less is a signal at the edge of its tolerance, flickering."""


def _redone(base: Any, subtask: Subtask, scene: Scene, states: np.ndarray, labels: np.ndarray, k: int,
            held: np.ndarray) -> int | None:
    """Where subtask `k` (not a grasp: the hand beside the object, hooked behind a handle) really ends, if
    its signal was lost in the subtask after it, the hand went `REDONE` or more away, and the signal came
    back before the hand moved the subtask's object (the step after which it holds for the last time
    before then); else None. A person whose hand reached the place, found it off, went up and came down
    again did the subtask with the last coming down. (`held` (T + 1, 3) [m]: the hand before each step.)"""
    done = subtask.done
    if done is None or isinstance(done, Grasped):
        return None
    after = np.flatnonzero(labels == k + 1)
    if len(after) < 2:
        return None
    base.set_state(states[after[0]])
    start = subtask.frame(scene, base.data).pos.copy()
    holds = []
    for t in after:
        base.set_state(states[t + 1])
        if np.abs(subtask.frame(scene, base.data).pos - start).max() >= STILL:
            break  # the object moves from here on: the next subtask is under way
        holds.append(bool(done(scene, base.data)))
    if all(holds) or not any(holds[int(np.argmin(holds)):]):
        return None  # never lost, or lost and not back before the object moved
    onset = len(holds) - 1 - int(np.argmin(holds[::-1]))  # the last step at which it did not hold
    away = np.linalg.norm(held[after[0]:after[0] + onset + 2] - held[after[0]], axis=1).max()
    if away < REDONE:
        return None
    return int(after[0]) + onset + 2 if onset + 1 < len(holds) else None


def segments_of(name: str, annotation: Annotation, actions: np.ndarray, openings: np.ndarray | None = None,
                changes: np.ndarray | None = None) -> list[Segment]:
    """A complete demo's segments, one per subtask (see `annotate`); `openings` (T,) [m] is the fingers'
    mean opening after each step, `changes` (T,) the largest change of any observation entry in each
    step (`still_steps`). Each segment keeps only the steps that move the work on (`tidy_steps`): what
    a person's pauses, hesitations and missed grasps add is left out."""
    out = []
    for k, (start, end) in enumerate(annotation.bounds()):
        frame = annotation.frames[k]
        assert frame is not None
        grips = actions[start:end, 3].astype(np.float64)
        fingers = None if openings is None else openings[start:end].astype(np.float64)
        targets = annotation.held[start:end] + ACTION_STEP * actions[start:end, :3].astype(np.float64)
        still = None if changes is None else still_steps(actions[start:end], changes[start:end])
        holding = start > 0 and float(actions[start - 1, 3]) <= SQUEEZE  # the segment before ended closed
        first, keep = tidy_steps(targets, grips, fingers, still, frame, annotation.held[start:end], holding)
        first += start
        targets, grips = targets[keep], grips[keep]
        closest = int(np.argmin(np.linalg.norm(targets - frame.pos, axis=1)))
        out.append(Segment(name, first, end, annotation.held[first].copy(), targets, grips,
                           None if fingers is None else fingers[keep], frame, closest, start + keep))
    return out


TRANSIT = 0.8 * ACTION_STEP
"""[m] the most a tidied segment moves its target in one step (the expert's free motion: `ACTION_STEP`)."""
FINE = 0.01
"""[m] near its reference a tidied step moves at most as far as its target is from the reference (as the
expert's proportional approach does), but this far at least."""


def tidy_steps(targets: np.ndarray, grips: np.ndarray, openings: np.ndarray | None, still: np.ndarray | None,
               frame: Frame, held: np.ndarray, holding: bool = False) -> tuple[int, np.ndarray]:
    """Where a segment's replay starts and the indices of the steps it replays, in order (`held` (L, 3)
    [m]: the hand before each step; `holding`: the fingers were closed when the segment began).

    - A segment that ends holding something and let go on the way leaves out, if it began holding,
      its steps from the letting go to its final grasp (a grasp that a person redid), and otherwise
      its steps from the first closing to where the fingers are open again before the final grasp
      (a grasp missed and its reopening): the approach before and the grasp after are replayed.
    - Steps that change nothing (`still`) are left out.
    - Slow steps are merged so that the target moves up to `TRANSIT` a step, and near the segment's
      reference no farther than it is from it (`FINE` at least): a person's half-pushed stick and
      careful corrections, replayed at the expert's pace. Steps whose finger command changes, or
      after which the fingers still move, keep their timing."""
    n = len(targets)
    squeeze = grips <= SQUEEZE
    order = np.arange(n)
    if squeeze[-1] and not squeeze.all():
        final = n - int(np.argmin(squeeze[::-1]))  # the final close
        if holding or squeeze[0]:  # it held something, let go and grasped again: it goes on holding
            order = np.r_[order[:int(np.argmin(squeeze))], order[final:]]
        elif squeeze[:final].any():  # closed on nothing and opened again: from before that to where it is open
            reopened = int(np.flatnonzero(squeeze[:final])[-1]) + 1
            wide = reopened
            if openings is not None:
                span = openings[reopened:final]
                wide = reopened + int(np.argmax(span >= 0.9 * span.max()))
            order = np.r_[order[:int(np.argmax(squeeze))], order[wide:]]
    if still is not None:
        moving = order[~still[order]]
        order = moving if len(moving) else order[-1:]
    first = int(order[0])
    fingers_move = np.zeros(n, bool)
    if openings is not None:
        fingers_move[1:] = np.abs(np.diff(openings)) >= STILL
    timed = np.r_[False, np.abs(np.diff(grips)) > REGRIP] | fingers_move
    reach = np.clip(np.linalg.norm(targets - frame.pos, axis=1), FINE, TRANSIT)
    keep: list[int] = []
    for i in order:
        if keep and not timed[i] and not timed[keep[-1]] and i != order[-1] \
                and np.linalg.norm(targets[i] - (targets[keep[-2]] if len(keep) > 1 else held[order[0]])) \
                <= min(reach[i], reach[keep[-1]]):
            keep[-1] = int(i)  # one step of the tidied segment goes from the one before to here
        else:
            keep.append(int(i))
    return first, np.asarray(keep, int)


def describe_subtasks(path: str | os.PathLike[str], demo: str | None = None) -> Iterator[str]:
    """`gym-fetch subtasks`: the task's subtasks, then one line per demo (`demo`: an index or name; None: all)
    saying the steps each subtask spans, as `annotate` cuts them from the saved states."""
    import gymnasium as gym

    from fetch.dataset.reader import open_dataset
    from fetch.dataset.validation import require_valid

    with open_dataset(path) as ds:
        names = ds.select(demo)
        require_valid(ds, names, images=False)
        env: Any = gym.make(ds.env_id, **ds.env_kwargs).unwrapped
        subtasks = type(env.task).subtasks
        yield f"{ds.env_id}: subtasks {', '.join(s.name for s in subtasks)}"
        for name in names:
            arrays = ds.arrays(name)
            a = annotate(env, subtasks, arrays["states"], arrays["actions"][:, 3])
            parts = ", ".join(f"{subtasks[k].name} {lo}-{hi - 1}" for k, (lo, hi) in enumerate(a.bounds()))
            yield f"{name}: {parts}" + ("" if a.complete else " (incomplete: not every subtask ended)")
