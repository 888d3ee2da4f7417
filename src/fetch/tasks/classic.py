"""The classic Fetch tasks (Reach, Push, PickPlace, Slide) with gymnasium-robotics' v4 semantics."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from fetch.robot import RobotConfig
from fetch.tasks.base import GRIPPER_PARTS, TABLE_TOP, FreeObject, Task, object_parts, sample_clear_xy


class Reach(Task):
    """Move the grip site to a point sampled in a 30 cm cube around its start."""

    name = "reach"
    success_rule = "grip site within 5 cm of the goal"
    robot = RobotConfig(block_gripper=True)
    parts = GRIPPER_PARTS
    achieved = "grip_pos"
    target_range = 0.15

    def build(self, spec: mujoco.MjSpec) -> None:
        pass

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              grip_start: np.ndarray) -> np.ndarray:
        return grip_start + rng.uniform(-self.target_range, self.target_range, size=3)


@dataclasses.dataclass(frozen=True)
class ObjectGoal:
    """The classic object-task parameters (gymnasium-robotics' BaseFetchEnv arguments)."""

    obj_range: float
    target_range: float
    target_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    target_in_the_air: bool = False
    min_start_distance: float = 0.1
    """[m] the object starts at least this far (xy) from the gripper."""


class _ObjectTask(Task):
    """An object on the table moved to a goal: Push, PickPlace, Slide."""

    parts = object_parts("object", "object0")
    achieved = "object_pos"
    success_rule = "object within 5 cm of the goal"
    params: ObjectGoal
    object_half_height = 0.025

    def build(self, spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name="object0", pos=[1.6, 0.3, TABLE_TOP + self.object_half_height])
        body.add_freejoint(name="object0:joint")
        self.add_object_geom(body)
        body.add_site(name="object0", size=[0.02, 0.02, 0.02], rgba=[1, 0, 0, 0])

    def add_object_geom(self, body: mujoco.MjsBody) -> None:
        body.add_geom(name="object0", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.025, 0.025, 0.025],
                      material="object_mat", mass=2.0, condim=3)

    def bind(self, model: mujoco.MjModel) -> None:
        self.object = FreeObject(model, "object0")

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              grip_start: np.ndarray) -> np.ndarray:
        p = self.params
        xy = sample_clear_xy(rng, grip_start, p.obj_range, [(grip_start, p.min_start_distance)])
        height = TABLE_TOP + self.object_half_height
        self.object.place(data, np.array([xy[0], xy[1], height]))
        goal = grip_start + rng.uniform(-p.target_range, p.target_range, size=3)
        goal += np.asarray(p.target_offset)
        goal[2] = height
        if p.target_in_the_air and rng.uniform() < 0.5:
            goal[2] += rng.uniform(0.0, 0.45)
        return goal


class Push(_ObjectTask):
    """Push a block, fingers closed, to a goal on the table."""

    name = "push"
    robot = RobotConfig(block_gripper=True, start_height=0.0)
    params = ObjectGoal(obj_range=0.15, target_range=0.15)


class PickPlace(_ObjectTask):
    """Pick a block and bring it to a goal on the table or, half of the time, up to 45 cm above it."""

    name = "pick_place"
    robot = RobotConfig(start_height=0.2)
    params = ObjectGoal(obj_range=0.15, target_range=0.15, target_in_the_air=True)


class Slide(_ObjectTask):
    """Hit a low-friction puck so it slides to a goal out of reach on a long table."""

    name = "slide"
    robot = RobotConfig(base_xy=(0.05, 0.48), block_gripper=True, start_height=-0.02,
                        workspace_low=(0.7, 0.35, 0.42), workspace_high=(1.5, 1.15, 0.9))
    params = ObjectGoal(obj_range=0.1, target_range=0.3, target_offset=(0.4, 0.0, 0.0))
    object_half_height = 0.02

    def build(self, spec: mujoco.MjSpec) -> None:
        table = spec.body("table0")
        table.pos = [1.32441906, 0.75018422, 0.2]
        top = spec.geom("table0")
        top.size = [0.625, 0.45, 0.2]
        top.friction = [0.1, 0.005, 0.0001]
        super().build(spec)

    def add_object_geom(self, body: mujoco.MjsBody) -> None:
        body.add_geom(name="object0", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.025, 0.02, 0],
                      material="object_mat", mass=2.0, condim=3, friction=[0.1, 0.005, 0.0001])
