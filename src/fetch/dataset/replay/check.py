"""Re-simulating saved demos: from their seed and from their saved states, compared bit for bit (the one
replay of every recorded format; `gym-fetch replay` runs it through `replay/replaying.py`)."""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np

from fetch.dataset.reader import Dataset


@dataclasses.dataclass(frozen=True)
class Deviation:
    """The largest difference found: its size and where."""

    value: float
    where: str


@dataclasses.dataclass(frozen=True)
class ReplayCheck:
    """How one demo's replay compares with what was recorded."""

    name: str
    steps: int
    reset: Deviation
    """`env.reset(seed)` vs the recorded first observation and `states[0]`."""
    observations: Deviation
    """Each step's observation vs `next_obs` (from the restored `states[0]`)."""
    states: Deviation
    """Each step's state vs `states[1:]`."""
    success_recorded: bool
    success_replayed: bool

    @property
    def exact(self) -> bool:
        return self.reset.value == 0 and self.observations.value == 0 and self.states.value == 0

    @property
    def largest(self) -> Deviation:
        return max((self.reset, self.observations, self.states), key=lambda d: d.value)


def make_replay_env(ds: Dataset) -> Any:
    """The dataset's env, unwrapped (no TimeLimit: demos may be longer than 50 steps)."""
    return gym.make(ds.env_id, **ds.env_kwargs).unwrapped


def other_model(ds: Dataset, env: Any) -> str | None:
    """Why a replay on `env` (from `make_replay_env`) need not be exact, or None when the dataset was
    recorded on this model: a line naming the two model hashes and the versions then and now. The
    physics of a task changes between releases (contacts, masses) and its MJB between MuJoCo
    versions, and a replay is bit for bit only on the model the demos were recorded on."""
    import mujoco

    import fetch

    recorded = str(ds.data_attrs.get("model_hash", ""))
    here = env.model_hash()
    if recorded in (here, env.legacy_model_hash()):
        return None
    then = ", ".join(f"{k} {ds.versions[k]}" for k in ("fetch", "mujoco") if k in ds.versions) or "versions unknown"
    return (f"note: {ds.path} was recorded on another model than this install's (model hash {recorded[:12]}, "
            f"here {here[:12]}; recorded with {then}, here fetch {fetch.__version__}, mujoco {mujoco.__version__}): "
            "a replay is exact only on the model it was recorded on, so a deviation here need not mean a damaged "
            "demo")


def largest_difference(replayed: np.ndarray, recorded: np.ndarray, label: str, row_offset: int = 0) -> Deviation:
    """The largest absolute difference (NaN counts as infinite) and its `label[row, column]`."""
    if replayed.size == 0:
        return Deviation(0.0, label)
    diff = np.abs(replayed - recorded)
    diff = np.where(np.isnan(diff), np.inf, diff)
    flat = int(np.argmax(diff))
    row, col = np.unravel_index(flat, diff.shape) if diff.ndim > 1 else (flat, 0)
    return Deviation(float(diff.flat[flat]), f"{label}[{int(row) + row_offset}, {int(col)}]")


def check_demo(ds: Dataset, name: str, env: Any | None = None) -> ReplayCheck:
    """Replay one demo: reset with its seed (compared with the start it recorded), restore
    `states[0]`, apply the recorded actions, compare every observation and state."""
    env = env if env is not None else make_replay_env(ds)
    group = ds.demo(name)
    keys = [k for k, _ in ds.layout.obs_sizes]
    return resimulate(name, env, int(group.attrs["seed"]), group["actions"][()], group["states"][()],
                      first={k: group[f"obs/{k}"][:1] for k in keys},
                      recorded_next={k: group[f"next_obs/{k}"][()] for k in keys},
                      success_recorded=bool(group["is_success"][()].any()))


def resimulate(name: str, env: Any, seed: int, actions: np.ndarray, states: np.ndarray,
               first: dict[str, np.ndarray], recorded_next: dict[str, np.ndarray],
               success_recorded: bool) -> ReplayCheck:
    """Reset `env` with `seed` (compared with `states[0]` and the `first` observation rows), restore
    `states[0]`, apply `actions`, compare every observation with `recorded_next` and every state
    with `states[1:]`. The one replay of both the HDF5 and the npz format."""
    keys = list(recorded_next)
    obs, _ = env.reset(seed=seed)
    start = env.get_state()
    reset_devs = [largest_difference(start[None], states[:1], "states")]
    reset_devs += [largest_difference(obs[k][None], first[k], f"obs/{k}") for k in keys if len(first[k])]
    reset = max(reset_devs, key=lambda d: d.value)

    env.set_state(states[0])
    replayed = {k: np.empty_like(recorded_next[k]) for k in keys}
    replayed_states = np.empty_like(states[1:])
    success = False
    for i, action in enumerate(actions):
        obs, _, _, _, info = env.step(action)
        for k in keys:
            replayed[k][i] = obs[k]
        env.get_state(out=replayed_states[i])
        success = success or info["is_success"] >= 1.0
    observations = max((largest_difference(replayed[k], recorded_next[k], f"next_obs/{k}") for k in keys),
                       key=lambda d: d.value, default=Deviation(0.0, "next_obs"))
    return ReplayCheck(name=name, steps=len(actions), reset=reset, observations=observations,
                       states=largest_difference(replayed_states, states[1:], "states", row_offset=1),
                       success_recorded=success_recorded, success_replayed=success)
