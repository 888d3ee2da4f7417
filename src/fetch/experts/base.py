"""What an expert is, and the proportional controller and finger servo every expert uses."""

from __future__ import annotations

import abc
import enum
from collections.abc import Mapping

import numpy as np

from fetch.robot import ACTION_STEP


class Stage(enum.Enum):
    """Where an expert is in its script (each expert uses some of these, in its own order)."""

    START = enum.auto()
    ABOVE = enum.auto()      # over the object, fingers open
    DESCEND = enum.auto()
    CLOSE = enum.auto()
    LIFT = enum.auto()
    CARRY = enum.auto()
    LOWER = enum.auto()
    RELEASE = enum.auto()
    RETREAT = enum.auto()
    OVER = enum.auto()       # behind the object, above it (push)
    DOWN = enum.auto()
    PUSH = enum.auto()
    PULL = enum.auto()       # the drawer's handle
    LINE_UP = enum.auto()    # slide: behind the puck on its line to the goal
    WATCH = enum.auto()      # slide: the puck is moving
    DONE = enum.auto()


class Expert(abc.ABC):
    """A scripted policy that reads only the observation dict: `expert.reset()`, then `expert(obs)`.

    `layout` names the slices of `obs["observation"]` (the env's `observation_layout`).
    """

    def __init__(self, layout: Mapping[str, slice], gain: float = 1.0) -> None:
        self.layout = dict(layout)
        self.gain = gain
        self.reset()

    def reset(self) -> None:
        """Forget the previous episode (call after every env.reset)."""
        self.stage = Stage.START
        self.timer = 0

    def part(self, obs: Mapping[str, np.ndarray], name: str) -> np.ndarray:
        return np.asarray(obs["observation"])[self.layout[name]]

    def move(self, grip: np.ndarray, target: np.ndarray, speed: float = 1.0) -> np.ndarray:
        """A proportional step of the grip site towards `target` [m], at most `speed` of full speed."""
        return np.clip(self.gain * (np.asarray(target) - grip) / ACTION_STEP, -speed, speed)

    @staticmethod
    def finger_servo(obs: Mapping[str, np.ndarray], layout: Mapping[str, slice], opening: float) -> float:
        """a[3] that drives each finger towards `opening` [m] (0 closed, 0.05 fully open).

        The finger actuators servo to (current opening + a[3]), so a[3] = opening - current
        commands `opening` itself; subtracting the motion expected in the next step keeps a
        fast-moving finger from overshooting into a wall.
        """
        vec = np.asarray(obs["observation"])
        state, per_step = vec[layout["gripper_state"]].mean(), vec[layout["gripper_vel"]].mean()
        return float(np.clip(opening - state - per_step, -1.0, 1.0))

    def advance(self, stage: Stage) -> None:
        self.stage, self.timer = stage, 0

    def __call__(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        action = self.act(obs)
        self.timer += 1
        return np.asarray(action, dtype=np.float32)

    @abc.abstractmethod
    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        """The 4-D action for this observation."""
