"""What a person's demos hold that is known to hurt learning: still steps, gripper chatter, regrasps,
a demo far longer than the rest, a success reached and lost. `generate` and `train` read the still
steps; `info` and `view` flag the rest, per demo, with where it happens. Flags inform: nothing is
dropped from a dataset because of them."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fetch.dataset.reader import READ_ERRORS
from fetch.errors import DatasetError

IDLE_ACTION = 0.05
"""[action units] a step that asks the hand to move less than this on every axis (2.5 mm) asks nothing."""
STILL = 1e-3
"""[m, m per step] a step in which no observation entry changes more than this left the scene as it was."""
REGRIP = 0.05
"""[action units] a change of the finger command larger than this is a new command."""
SQUEEZE = -0.5
"""A finger command at or below this closes the fingers on something (a pad's X: -1)."""
IDLE_FLAG = 10
"""[steps] still steps in a row, before the task is done, that are worth a flag (0.4 s at 25 Hz)."""
CHATTER = 10
"""[steps] two switches between closing and opening the fingers closer than this are chatter."""
HORIZON_MARGIN = 1.25
"""A policy, or a generation attempt, is given this many times the steps its slower demos took."""
LONG = 2.0
"""a demo this many times longer than the dataset's median is far longer than the rest."""


def still_steps(actions: np.ndarray, changes: np.ndarray) -> np.ndarray:
    """(T,) bool: the steps that changed nothing: the hand asked to stay, the finger command as before,
    and no observation entry changed more than `STILL` (`changes`: (T,) the largest change of any
    entry over the step). A person's pause, a look around, a hand resting on a grasp already made;
    fingers that are still closing, or an object still moving, are change."""
    actions = np.asarray(actions, np.float64)
    asked = np.abs(actions[:, :3]).max(axis=1) >= IDLE_ACTION
    regrip = np.r_[True, np.abs(np.diff(actions[:, 3])) > REGRIP]
    return ~asked & ~regrip & (np.asarray(changes) < STILL)


def pose_columns(layout: Mapping[str, slice] | None, size: int) -> np.ndarray:
    """The observation's entries that say where things are (every part but the velocities: `*vel*`), of
    `size` entries in all; all of them without a layout. A velocity's change is no motion: a block
    held in soft fingers (v4's contacts, mujoco 3.3) spins back and forth at a few mrad a step."""
    if layout is None:
        return np.arange(size)
    return np.array([i for name, part in layout.items() if "vel" not in name
                     for i in range(*part.indices(size))], dtype=int)


def observation_changes(obs: np.ndarray, next_obs: np.ndarray, columns: np.ndarray | None = None) -> np.ndarray:
    """(T,) the largest change over each step of the observation's `columns` (all where None; see
    `pose_columns`)."""
    change = np.abs(np.asarray(next_obs, np.float64) - np.asarray(obs, np.float64))
    return (change if columns is None else change[:, columns]).max(axis=1)


def layout_of(env_id: str) -> dict[str, slice] | None:
    """The observation layout of a registered id (None: not one of ours, or it cannot be made)."""
    import gymnasium as gym

    try:
        env = gym.make(env_id)
    except Exception:  # an unknown or broken id: the flags then read every entry
        return None
    try:
        return dict(env.unwrapped.observation_layout)  # type: ignore[attr-defined]
    finally:
        env.close()


def first_success(is_success: np.ndarray) -> int | None:
    """[steps] how many steps until `is_success` first held (None: never)."""
    hits = np.flatnonzero(np.asarray(is_success) > 0)
    return int(hits[0]) + 1 if len(hits) else None


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The [start, end) step ranges where `mask` holds, in order."""
    edges = np.diff(np.r_[0, np.asarray(mask, np.int8), 0])
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True))


@dataclasses.dataclass(frozen=True)
class Flag:
    """One thing in a demo known to hurt learning: what, how many, and where (steps, 0-based)."""

    kind: str
    """idle, chatter, regrasp, long, lost."""
    count: int
    where: tuple[tuple[int, int], ...]
    """[start, end) step ranges."""
    text: str

    def as_dict(self) -> dict[str, object]:
        return {"kind": self.kind, "count": self.count, "where": [list(w) for w in self.where], "text": self.text}


FLAG_KINDS = {
    "idle": f"stretches of {IDLE_FLAG} or more steps that change nothing, before the task is done (a policy "
            "learns to rest there)",
    "chatter": f"the fingers were told to close and to open again (or the reverse) within {CHATTER} steps",
    "regrasp": "the fingers closed on something more than once before the task was done",
    "long": f"more than {LONG:g} times the dataset's median length",
    "lost": "success reached, then lost before the demo's end",
}
"""What each flag means, as `info` and `view` explain it."""


def _where(ranges: Sequence[tuple[int, int]]) -> str:
    return ", ".join(f"{a}-{b - 1}" if b - a > 1 else f"{a}" for a, b in ranges)


def demo_flags(arrays: Mapping[str, np.ndarray], median_length: float | None = None,
               layout: Mapping[str, slice] | None = None) -> list[Flag]:
    """The flags of one demo (its arrays as the reader gives them: actions, obs, next_obs, is_success;
    `layout`: the observation's, for `pose_columns`)."""
    actions = np.asarray(arrays["actions"], np.float64)
    steps = len(actions)
    if steps == 0:
        return []
    success = np.asarray(arrays["is_success"]) > 0
    done = first_success(success) or steps
    flags: list[Flag] = []
    obs = np.asarray(arrays["obs/observation"])
    columns = pose_columns(layout, obs.shape[1])
    still = still_steps(actions, observation_changes(obs, arrays["next_obs/observation"], columns))
    idle = [(a, b) for a, b in runs(still[:done]) if b - a >= IDLE_FLAG]
    if idle:
        total = sum(b - a for a, b in idle)
        flags.append(Flag("idle", total, tuple(idle), f"idle {total} steps at {_where(idle)}"))
    grip = actions[:, 3]
    changes = np.flatnonzero(np.diff((grip <= SQUEEZE).astype(np.int8)) != 0) + 1  # X pressed: closed <-> open
    close = [(int(a), int(b) + 1) for a, b in zip(changes[:-1], changes[1:], strict=True) if b - a < CHATTER]
    if close:
        flags.append(Flag("chatter", len(close) + 1, tuple(close),
                          f"gripper switched {len(close) + 1} times within {CHATTER} steps at {_where(close)}"))
    squeezed = runs(grip[:done] <= SQUEEZE)
    if len(squeezed) > 1:
        flags.append(Flag("regrasp", len(squeezed), tuple(squeezed),
                          f"fingers closed {len(squeezed)} times before success, at {_where(squeezed)}"))
    if median_length and steps > LONG * median_length:
        flags.append(Flag("long", steps, ((0, steps),),
                          f"{steps} steps, {steps / median_length:.1f}x the median {median_length:g}"))
    lost = [(a, b) for a, b in runs(~success) if a > 0 and success[a - 1]]
    if lost:
        flags.append(Flag("lost", len(lost), tuple(lost),
                          f"success lost {len(lost)} time(s), at {_where(lost)}"))
    return flags


def dataset_flags(ds: Any) -> dict[str, list[Flag]]:
    """The flags of every readable demo of a dataset (`reader.Dataset`) that has any, by demo name."""
    unreadable: tuple[type[Exception], ...] = (DatasetError, IndexError, *READ_ERRORS)  # malformed: `validate` says
    lengths = []
    for name in ds.demo_names:
        try:
            attrs = ds.attrs(name)
            if attrs.get("success"):
                lengths.append(int(attrs["num_samples"]))
        except unreadable:
            continue
    median = float(np.median(lengths)) if lengths else None
    layout = layout_of(str(ds.env_id))
    out: dict[str, list[Flag]] = {}
    for name in ds.demo_names:
        try:
            flags = demo_flags(ds.arrays(name), median, layout)
        except unreadable:
            continue  # `validate` says what is wrong with it
        if flags:
            out[name] = flags
    return out


def describe_flags(found: Mapping[str, Sequence[Flag]], demos: int, shown: int = 20) -> list[str]:
    """`info`'s lines on what was flagged: a count per kind (with what it means), then a line per demo."""
    if not found:
        return [f"habits      none of {demos} demos has what is known to hurt learning"]
    counts: dict[str, int] = {}
    for flags in found.values():
        for f in flags:
            counts[f.kind] = counts.get(f.kind, 0) + 1
    lines = [f"habits      {len(found)} of {demos} demos flagged (flags inform; nothing is dropped): "
             + ", ".join(f"{kind} {n}" for kind, n in counts.items())]
    lines += [f"              {kind}: {FLAG_KINDS[kind]}" for kind in counts]
    for name in list(found)[:shown]:
        lines.append(f"  {name}: " + "; ".join(f.text for f in found[name]))
    if len(found) > shown:
        lines.append(f"  ... and {len(found) - shown} more (`gym-fetch view` shows every one)")
    return lines
