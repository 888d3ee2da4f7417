"""One attempt's recording: preallocated arrays filled step by step, handed over as a `Demo`."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from fetch.dataset.schema import Layout


@dataclasses.dataclass
class Demo:
    """A finished episode: arrays keyed by their path in the demo group, and its attributes."""

    arrays: dict[str, np.ndarray]
    attrs: dict[str, Any]

    @property
    def num_samples(self) -> int:
        return int(self.arrays["actions"].shape[0])

    @property
    def success(self) -> bool:
        return bool(self.attrs["success"])


class EpisodeBuffer:
    """Records one episode into preallocated arrays (grown by doubling past `capacity`).

    `begin` takes the reset's observation and state; `record` one step: the action applied, what
    the env returned, the state after it and, for a device that perturbs what it sends on purpose,
    the action it meant (`label`; the episode then gets `expert_actions`, the applied action standing
    in for a step without one), and, where a person can take over from a policy, who drove and what
    the policy proposed (`intervention`, `policy_actions`). Recording copies values in; nothing
    aliases the env.
    Camera images are not recorded here: the writer renders them from the states.
    """

    def __init__(self, layout: Layout, capacity: int = 64) -> None:
        self.layout = layout
        self._capacity = max(int(capacity), 1)
        self._allocate(self._capacity)
        self.length = 0
        self.labelled = False
        self.corrected = False

    def _allocate(self, capacity: int) -> None:
        n = capacity
        self.actions = np.zeros((n, 4), np.float32)
        self.labels = np.zeros((n, 4), np.float32)
        self.interventions = np.zeros(n, np.uint8)
        self.proposals = np.zeros((n, 4), np.float32)
        self.obs = {key: np.zeros((n + 1, size)) for key, size in self.layout.obs_sizes}
        self.rewards = np.zeros(n)
        self.terminated = np.zeros(n, bool)
        self.truncated = np.zeros(n, bool)
        self.is_success = np.zeros(n, np.uint8)
        self.states = np.zeros((n + 1, self.layout.state_size))
        self.timestamps = np.zeros(n)

    def _grow(self) -> None:
        saved = {name: getattr(self, name) for name in ("actions", "labels", "interventions", "proposals", "rewards",
                                                         "terminated", "truncated", "is_success", "states",
                                                         "timestamps")}
        obs = self.obs
        self._capacity *= 2
        self._allocate(self._capacity)
        for name, array in saved.items():
            getattr(self, name)[: len(array)] = array
        for key, array in obs.items():
            self.obs[key][: len(array)] = array

    def begin(self, obs: Mapping[str, np.ndarray], state: np.ndarray) -> None:
        """Start a new episode from the reset's observation and `env.get_state()`."""
        self.length = 0
        self.labelled = self.corrected = False
        for key, rows in self.obs.items():
            rows[0] = obs[key]
        self.states[0] = state

    def state_row(self) -> np.ndarray:
        """Where the state after the next recorded step goes (for `env.get_state(out=...)`)."""
        if self.length == self._capacity:
            self._grow()
        return self.states[self.length + 1]

    def record(self, action: np.ndarray, obs: Mapping[str, np.ndarray], reward: float, terminated: bool,
               truncated: bool, success: bool, timestamp: float, label: np.ndarray | None = None,
               intervention: bool | None = None, proposal: np.ndarray | None = None) -> None:
        """Append one step; the state after it must already be in `state_row()`."""
        t = self.length
        if t == self._capacity:
            self._grow()
        self.actions[t] = action
        if label is not None:
            self.labels[t] = np.clip(label, -1.0, 1.0)
            self.labelled = True
        else:
            self.labels[t] = action
        if intervention is not None:
            self.interventions[t] = intervention
            self.proposals[t] = np.clip(proposal if proposal is not None else action, -1.0, 1.0)
            self.corrected = True
        for key, rows in self.obs.items():
            rows[t + 1] = obs[key]
        self.rewards[t] = reward
        self.terminated[t] = terminated
        self.truncated[t] = truncated
        self.is_success[t] = success
        self.timestamps[t] = timestamp
        self.length = t + 1

    def rewind(self, steps: int) -> np.ndarray:
        """Forget the last `steps` steps (all there are, at most); returns the state the episode is then in,
        for `env.set_state` (a view into the buffer, valid until the next `record`)."""
        self.length = max(self.length - int(steps), 0)
        return self.states[self.length]

    def demo(self, attrs: Mapping[str, Any]) -> Demo:
        """The episode so far as a `Demo` of copies (the buffer can be reused at once)."""
        t = self.length
        arrays: dict[str, np.ndarray] = {"actions": self.actions[:t].copy()}
        if self.labelled:
            arrays["expert_actions"] = self.labels[:t].copy()
        if self.corrected:
            arrays["intervention"] = self.interventions[:t].copy()
            arrays["policy_actions"] = self.proposals[:t].copy()
        for key, rows in self.obs.items():
            arrays[f"obs/{key}"] = rows[:t].copy()
            arrays[f"next_obs/{key}"] = rows[1 : t + 1].copy()
        dones = np.zeros(t, np.uint8)
        if t:
            dones[-1] = 1
        arrays.update(rewards=self.rewards[:t].copy(), dones=dones, terminated=self.terminated[:t].copy(),
                      truncated=self.truncated[:t].copy(), is_success=self.is_success[:t].copy(),
                      states=self.states[: t + 1].copy(), timestamps=self.timestamps[:t].copy())
        return Demo(arrays=arrays, attrs={**attrs, "num_samples": t})
