"""A private copy of a classic object task that an expert plans in, exact while it sees every step."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import mujoco
import numpy as np

from fetch.env import FetchEnv

Observation = Mapping[str, np.ndarray]


class Twin:
    """The expert's own copy of the task (`FetchEnv(task=...)`), kept in step with the episode.

    A classic object task starts as gymnasium-robotics' does: the settled robot, with only the
    object's xy and the goal drawn. So the first observation says the whole start, and the twin
    begins exactly there (`start`). Stepped with each action the expert returned, it stays
    bit-identical to the episode as long as the env received those actions unchanged; the first
    observation that differs (action noise, a pad's rounding, another task's start) puts it out of
    step for the rest of the episode (`in_step`), and the expert goes on without it.
    """

    def __init__(self, env: FetchEnv) -> None:
        self.env = env
        self.in_step = False
        self.obs: Observation = {}
        self._object = env.task.object.qpos  # type: ignore[attr-defined]
        self._object_xy = env.observation_layout["object_pos"]

    def start(self, obs: Observation) -> None:
        """Begin as the episode whose first observation is `obs` began."""
        xy = np.asarray(obs["observation"])[self._object_xy][:2].copy()
        goal = np.asarray(obs["desired_goal"], dtype=np.float64).copy()

        def place(data: mujoco.MjData) -> np.ndarray:
            data.qpos[self._object:self._object + 2] = xy
            return goal

        self.obs = self.env.reset_like(place)[0]
        self.in_step = _same(self.obs, obs)

    def follow(self, action: np.ndarray, obs: Observation) -> None:
        """Take the step the episode took with `action`, if still in step, and check it gave `obs`."""
        if self.in_step:
            self.obs = self.env.step(action)[0]
            self.in_step = _same(self.obs, obs)

    def play(self, policy: Callable[[Observation], np.ndarray], steps: int) -> float:
        """[m] how far from the goal the task's achieved goal is after `steps` steps of `policy` from
        the twin's present state; the twin is put back in that state afterwards."""
        saved, obs = self.env.get_state(), self.obs
        for _ in range(steps):
            obs = self.env.step(policy(obs))[0]
        self.env.set_state(saved)
        return float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"]))


def _same(mine: Observation, theirs: Observation) -> bool:
    return all(np.array_equal(mine[key], theirs[key]) for key in ("observation", "desired_goal"))
