"""The source demos of a generation run: loaded, cut into subtask segments, fingerprinted."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
from typing import Any

import gymnasium as gym
import numpy as np

from fetch.dataset.habits import HORIZON_MARGIN, first_success, observation_changes, pose_columns
from fetch.dataset.reader import open_dataset
from fetch.dataset.validation import require_valid
from fetch.errors import FetchError
from fetch.generate.segments import Segment, annotate, segments_of, to_frame
from fetch.tasks import registered_horizon
from fetch.tasks.subtasks import GOAL, Grasped, Hooked

SETTLE_FROM = 0.02
"""[m] a source of a task whose last segment carries its object (grasped or hooked before it: a block, a
lid, a drawer's handle), ending with its achieved goal farther than this from the desired one (a person
who stopped once success showed, at the edge of the 5 cm region), has its last segment carry it the rest
of the way (`Segment.settle`); the experts place within 1 cm and are replayed as they are. A pushed
object (Push) is not carried: shifting the push moves where the hand meets it, and that is left as it
was (pushed along its line instead, the generated pushes ended no nearer: 2.7 against 2.9 cm)."""


@dataclasses.dataclass(frozen=True)
class Sources:
    """Segments of every usable source demo (`segments[d][k]`: demo d, subtask k)."""

    path: str
    env_id: str
    env_kwargs: dict[str, Any]
    subtasks: tuple[str, ...]
    segments: tuple[tuple[Segment, ...], ...]
    skipped: tuple[str, ...]
    """successful demos that could not be cut into every subtask (a signal never fired)."""
    fingerprint: str
    """SHA-256 of the used demos' names, seeds, actions and states: a resumed run must use the same."""

    took: tuple[int, ...] = ()
    """per used demo, the steps its tidied segments replay before its first success."""

    def attempt_steps(self, hold: int) -> int:
        """[steps] how long an attempt may take: the task's registered horizon, or more where a source
        demo's tidied segments take longer to succeed (times `HORIZON_MARGIN`, plus the `hold` steps
        success must hold). People's demos are slower than the task's 50 steps; tidied, most fit in
        them again."""
        return max(registered_horizon(self.env_id), math.ceil(HORIZON_MARGIN * max(self.took, default=0)) + hold)


def load_sources(path: str | os.PathLike[str]) -> Sources:
    """Read a dataset and cut each successful demo into its task's subtasks."""
    with open_dataset(path) as ds:
        require_valid(ds)
        env = gym.make(ds.env_id, **ds.env_kwargs)
        base: Any = env.unwrapped
        subtasks = type(base.task).subtasks
        if not subtasks:
            raise FetchError(f"{ds.env_id} declares no subtasks (Task.subtasks), so it cannot be generated from")
        digest = hashlib.sha256()
        columns = pose_columns(base.observation_layout, base.observation_space["observation"].shape[0])
        segments, skipped, took = [], [], []
        # The last segment carries the object (grasped or hooked before it): moving the hand moves it.
        carried = any(isinstance(s.done, Grasped | Hooked) for s in subtasks[:-1])
        on_object = subtasks[-1].reference != GOAL  # anchored on what it carries: ends relative to the goal
        for name in ds.demo_names:
            attrs = ds.attrs(name)
            if not attrs.get("success"):
                continue
            arrays = ds.arrays(name)
            annotation = annotate(base, subtasks, arrays["states"], arrays["actions"][:, 3])
            if not annotation.complete:
                skipped.append(name)
                continue
            changes = observation_changes(arrays["obs/observation"], arrays["next_obs/observation"], columns)
            cut = segments_of(name, annotation, arrays["actions"], _openings(base, arrays), changes)
            if carried:
                last = cut[-1]
                settle = np.asarray(arrays["next_obs/desired_goal"][-1] - arrays["next_obs/achieved_goal"][-1],
                                    np.float64)
                if np.linalg.norm(settle) > SETTLE_FROM:
                    last = dataclasses.replace(last, settle=settle)
                if on_object:
                    goal = to_frame(last.frame, np.asarray(arrays["obs/desired_goal"][last.start], np.float64))
                    last = dataclasses.replace(last, goal=goal, settle_by=last.length - 1)
                cut[-1] = last
            segments.append(tuple(cut))
            done = first_success(arrays["is_success"]) or len(changes)
            took.append(sum(int(np.sum(s.steps < done)) for s in cut if s.steps is not None))
            digest.update(f"{name}:{attrs['seed']}".encode())
            digest.update(arrays["actions"].tobytes())
            digest.update(arrays["states"].tobytes())
        env.close()
        if not segments:
            raise FetchError(f"{ds.path}: none of its {len(ds.demo_names)} demos is a success that can be cut into "
                             f"the subtasks of {ds.env_id} ({', '.join(s.name for s in subtasks)})")
        return Sources(str(ds.path.resolve()), ds.env_id, ds.env_kwargs, tuple(s.name for s in subtasks),
                       tuple(segments), tuple(skipped), digest.hexdigest(), tuple(took))


def _openings(base: Any, arrays: dict[str, np.ndarray]) -> np.ndarray | None:
    """(T,) [m] the fingers' mean opening after each step of a demo (None: no fingers observed)."""
    fingers = base.observation_layout.get("gripper_state")
    if fingers is None:
        return None
    return np.asarray(arrays["next_obs/observation"][:, fingers], np.float64).mean(axis=1)
