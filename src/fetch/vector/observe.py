"""Observations, rewards and infos of many worlds at once, from their sensors, goals and joints."""

from __future__ import annotations

import math
from typing import NamedTuple, cast

import mujoco
import numpy as np

from fetch import observation as ob
from fetch.tasks.base import Task, reward

Obs = dict[str, np.ndarray]


class _Rows(NamedTuple):
    """A world's qpos row where a task's `facts` reads `data.qpos` (the drawers' opening)."""

    qpos: np.ndarray


class BatchObserver:
    """What `FetchEnv._observe` computes for one world, for N. The distance is `math.dist` and success the
    task's scalar rule per world: numpy's norm differs from `math.dist` in the last bit (18 % of random
    pairs), which `info["distance"]` and a dense reward would show."""

    def __init__(self, task: Task, observer: ob.Observer, reward_type: str) -> None:
        self.task, self.observer, self.reward_type = task, observer, reward_type
        self.achieved = observer.layout[task.achieved]

    def __call__(self, sensordata: np.ndarray, goals: np.ndarray,
                 qpos: np.ndarray) -> tuple[Obs, np.ndarray, dict[str, np.ndarray]]:
        """(observations, rewards, infos) of worlds with these (N, ...) sensor readings, goals and qpos rows."""
        vectors = self.observer.batch(sensordata)
        achieved = vectors[:, self.achieved].copy()
        task = self.task
        distance, success, facts = [], [], []
        for k, (a, g) in enumerate(zip(achieved.tolist(), goals.tolist(), strict=True)):
            d = math.dist(a, g)
            distance.append(d)
            success.append(1.0 if task.success(a, g, d) else 0.0)
            facts.append(task.facts(cast(mujoco.MjData, _Rows(qpos[k])), vectors[k]))
        info = {"is_success": np.array(success), "distance": np.array(distance)}
        for key in facts[0]:
            info[key] = np.array([f[key] for f in facts], dtype=np.float64)
        rewards = reward(self.reward_type, info["is_success"], info["distance"])
        return {"observation": vectors, "achieved_goal": achieved, "desired_goal": goals}, rewards, info
