"""The classic Fetch tasks (Reach, Push, PickPlace, Slide): gymnasium-robotics' Fetch*-v4, reproduced.

Each loads its scene from gymnasium-robotics' own task file, starts as that suite starts (see
`fetch.compiled.settle_classic`) and draws its object and goal from `env.np_random` in the order
the classic `_reset_sim` and `_sample_goal` do, so a seed gives the same start and goal.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import mujoco
import numpy as np

from fetch.robot import RobotConfig
from fetch.tasks.base import GRIPPER_PARTS, FreeObject, Start, Task, object_parts, sample_clear_xy
from fetch.tasks.subtasks import GOAL, Beside, Grasped, Lifted, Subtask


class _ClassicTask(Task):
    """A classic scene: everything is in gymnasium-robotics' task file, and the start state (the
    base and object parked as the classic `initial_qpos` says, the arm settled) is loaded, so the
    robot config names only the scene, the workspace (none) and whether the fingers are held shut."""

    def build(self, spec: mujoco.MjSpec) -> None:
        pass


class Reach(_ClassicTask):
    """Move the grip site to a point sampled in a 30 cm cube around its start."""

    name = "reach"
    instruction = "move the gripper to the goal"
    expert = "fetch.experts.motion:Reach"
    success_rule = "grip site within 5 cm of the goal"
    robot = RobotConfig(scene="reach.xml", workspace=None, block_gripper=True)
    parts = GRIPPER_PARTS
    achieved = "grip_pos"
    mirrors = True
    subtasks = (Subtask("reach", GOAL, None),)
    target_range = 0.15

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              start: Start) -> np.ndarray:
        return start.grip + rng.uniform(-self.target_range, self.target_range, size=3)


@dataclasses.dataclass(frozen=True)
class ObjectGoal:
    """The classic object-task parameters (gymnasium-robotics' BaseFetchEnv arguments)."""

    obj_range: float
    target_range: float
    target_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    target_in_the_air: bool = False
    min_start_distance: float = 0.1
    """[m] the object starts at least this far (xy) from the gripper."""


class _ObjectTask(_ClassicTask):
    """An object on the table moved to a goal: Push, PickPlace, Slide."""

    parts = object_parts("object", "object0")
    achieved = "object_pos"
    success_rule = "object within 5 cm of the goal"
    params: ClassVar[ObjectGoal]

    def bind(self, model: mujoco.MjModel) -> None:
        self.object = FreeObject(model, "object0")

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              start: Start) -> np.ndarray:
        p = self.params
        # Only the object's xy is drawn (redrawn until clear of the grip, as there); its height,
        # orientation and velocity stay as settled.
        xy = sample_clear_xy(rng, start.grip, p.obj_range, [(start.grip, p.min_start_distance)])
        data.qpos[self.object.qpos:self.object.qpos + 2] = xy
        goal = start.grip + rng.uniform(-p.target_range, p.target_range, size=3)
        goal += np.asarray(p.target_offset)
        goal[2] = start.object_z if start.object_z is not None else np.nan
        if p.target_in_the_air and rng.uniform() < 0.5:
            goal[2] += rng.uniform(0.0, 0.45)
        return goal


class Push(_ObjectTask):
    """Push a block, fingers closed, to a goal on the table."""

    name = "push"
    instruction = "push the block to the goal"
    expert = "fetch.experts.motion:Push"
    robot = RobotConfig(scene="push.xml", workspace=None, block_gripper=True)
    params = ObjectGoal(obj_range=0.15, target_range=0.15)
    mirrors = True
    # Both parts are framed along the line from the object to the goal.
    subtasks = (Subtask("approach", "object0", Beside("object0"), heading=GOAL),
                Subtask("push", GOAL, None, heading="object0"))


LIFTED_Z = 0.445
"""[m] PickPlace's block is lifted once its centre is 2 cm above its rest on the table (0.425)."""


class PickPlace(_ObjectTask):
    """Pick a block and bring it to a goal on the table or, half of the time, up to 45 cm above it."""

    name = "pick_place"
    instruction = "pick up the block and bring it to the goal"
    expert = "fetch.experts:pick_place"
    robot = RobotConfig(scene="pick_and_place.xml", workspace=None)
    params = ObjectGoal(obj_range=0.15, target_range=0.15, target_in_the_air=True)
    mirrors = True
    # Lifted before it is carried: a place segment that starts from the table, carried over to a goal
    # at another height, blends the hand into the table and drags the block (docs/generate.md).
    subtasks = (Subtask("grasp", "object0", Grasped("object0")),
                Subtask("lift", "object0", Lifted("object0", "object0", LIFTED_Z)),
                Subtask("place", GOAL, None))


class Slide(_ObjectTask):
    """Hit a low-friction puck so it slides to a goal out of reach on a long table."""

    name = "slide"
    instruction = "slide the puck to the goal"
    expert = "fetch.experts:slide"
    robot = RobotConfig(scene="slide.xml", workspace=None, block_gripper=True)
    params = ObjectGoal(obj_range=0.1, target_range=0.3, target_offset=(0.4, 0.0, 0.0))
    subtasks = (Subtask("slide", "object0", None, heading=GOAL),)
