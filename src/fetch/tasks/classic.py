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
    """Hit a low-friction puck so it slides to a goal out of reach on a long table.

    The classic layout parks the robot so far back that at table height its hand reaches only
    x ~ 1.38 m and tops out at ~0.8 m/s: no push could make the puck glide past ~1.55 m, yet
    goals reach 1.69 m. Here the robot stands 20 cm closer and the table's near end is 6 cm
    shorter (clear of the base); the hand starts where the classic one does, and the puck and
    goal are sampled as in the classic suite, in the same places.
    """

    name = "slide"
    robot = RobotConfig(base_xy=(0.25, 0.48), start_shift_x=-0.2, block_gripper=True, start_height=-0.02,
                        workspace_low=(0.8, 0.35, 0.42), workspace_high=(1.65, 1.15, 0.9))
    params = ObjectGoal(obj_range=0.1, target_range=0.3, target_offset=(0.4, 0.0, 0.0))
    object_half_height = 0.02
    table_x = (0.76, 1.94941906)
    """[m] the table's near and far ends (the classic table spans 0.70 to 1.95)."""

    def build(self, spec: mujoco.MjSpec) -> None:
        near, far = self.table_x
        spec.body("table0").pos = [(near + far) / 2, 0.75018422, 0.2]
        top = spec.geom("table0")
        top.size = [(far - near) / 2, 0.45, 0.2]
        top.friction = [0.1, 0.005, 0.0001]
        if hasattr(mujoco.mjtEnableBit, "mjENBL_MULTICCD"):
            # mujoco 3.x's native convex collider, asked for several contacts, now and then
            # reports the gliding puck 29 cm deep in the table and fires it off at 5 m/s
            # (measured on 3.3.0: 1 episode in 60). libccd does not. 4.x is not affected.
            spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
        super().build(spec)

    def add_object_geom(self, body: mujoco.MjsBody) -> None:
        body.add_geom(name="object0", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.025, 0.02, 0],
                      material="object_mat", mass=2.0, condim=3, friction=[0.1, 0.005, 0.0001])
