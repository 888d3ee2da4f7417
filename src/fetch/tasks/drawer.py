"""Drawer-open and Drawer-close: a cabinet with a drawer on a 20 cm slide, handle facing the robot."""

from __future__ import annotations

import mujoco
import numpy as np

from fetch import observation as ob
from fetch.robot import RobotConfig
from fetch.tasks.base import GRIP, GRIPPER_PARTS, TABLE_TOP, Start, Task, box_geom, mocap_index
from fetch.tasks.subtasks import Hooked, Subtask

HOOK = Subtask("hook", "handle", Hooked("handle", behind=0.028, tolerance=(0.012, 0.04, 0.012)))
"""Closed fingers in the slot behind the handle bar (its centre 2.8 cm behind the bar's)."""

SLIDE = 0.20
"""[m] the drawer's travel."""
OPEN_AT_LEAST = 0.15
"""[m] Drawer-open succeeds from this opening on (the handle is within 5 cm of its goal)."""
CLOSED_AT_MOST = 0.05
"""[m] Drawer-close succeeds up to this opening."""
CABINET = (0.12, 0.15, 0.06)
"""[m] the cabinet's outer half-sizes: 24 cm deep, 30 cm wide, 12 cm tall."""
HANDLE_X = -0.18
"""[m] the handle bar's centre from the cabinet's centre along x: 6 cm in front of the front
face, leaving a 4 cm gap behind the bar for the fingers (2.7 cm thick) to hook."""
HANDLE_Z = 0.06
"""[m] height of the handle above the table."""


def add_cabinet(spec: mujoco.MjSpec) -> None:
    """A mocap cabinet (fixed in an episode, placed at reset) with a drawer on a slide joint."""
    hx, hy, hz = CABINET
    t = 0.005  # half wall thickness
    cab = spec.worldbody.add_body(name="cabinet", mocap=True, pos=[1.9, 0.3, TABLE_TOP])
    box_geom(cab, "cabinet_bottom", [hx, hy, t], [0, 0, t], "wood_mat")
    box_geom(cab, "cabinet_top", [hx, hy, t], [0, 0, 2 * hz - t], "wood_mat")
    for side in (-1, 1):
        box_geom(cab, f"cabinet_side{side + 1}", [hx, t, hz - 2 * t], [0, side * (hy - t), hz], "wood_mat")
    box_geom(cab, "cabinet_back", [t, hy - 2 * t, hz - 2 * t], [hx - t, 0, hz], "wood_mat")
    cab.add_site(name="cabinet", size=[0.01, 0.01, 0.01], rgba=[0, 0, 0, 0])

    drawer = cab.add_body(name="drawer", pos=[0, 0, 0])
    drawer.add_joint(name="drawer:slide", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[-1, 0, 0],
                     range=[0, SLIDE], limited=mujoco.mjtLimited.mjLIMITED_TRUE, damping=20.0,
                     armature=0.1)
    inner_y = hy - 2 * t - 0.004  # 4 mm play on each side
    box_geom(drawer, "drawer_front", [0.006, hy - 0.01, hz - 0.012], [-hx - 0.006, 0, hz], "wood_mat",
             mass=0.3)
    box_geom(drawer, "drawer_bottom", [hx - 0.015, inner_y, 0.004], [-0.005, 0, 0.016], "wood_mat", mass=0.3)
    for side in (-1, 1):
        box_geom(drawer, f"drawer_side{side + 1}", [hx - 0.015, 0.004, 0.03],
                 [-0.005, side * (inner_y - 0.004), 0.05], "wood_mat", mass=0.1)
    box_geom(drawer, "drawer_back", [0.004, inner_y, 0.03], [hx - 0.024, 0, 0.05], "wood_mat", mass=0.1)
    box_geom(drawer, "handle_bar", [0.008, 0.05, 0.008], [HANDLE_X, 0, HANDLE_Z], "handle_mat", mass=0.05)
    post_len = (-hx - 0.012) - (HANDLE_X + 0.008)
    for side in (-1, 1):
        box_geom(drawer, f"handle_post{side + 1}", [post_len / 2, 0.006, 0.006],
                 [HANDLE_X + 0.008 + post_len / 2, side * 0.044, HANDLE_Z], "handle_mat", mass=0.01)
    drawer.add_site(name="handle", pos=[HANDLE_X, 0, HANDLE_Z], size=[0.01, 0.01, 0.01], rgba=[0, 0, 0, 0])


class _DrawerTask(Task):
    # The gripper starts 20 cm above the table: its fingertips clear the cabinet's top by 5 cm.
    robot = RobotConfig(start_height=0.26)
    parts = (
        *GRIPPER_PARTS,
        ob.site_pos("cabinet_pos", "cabinet"),
        ob.site_pos("handle_pos", "handle"),
        ob.rel_pos("handle_rel_pos", "handle", GRIP),
        ob.joints("drawer_qpos", ("drawer:slide",)),
        ob.joints("drawer_qvel", ("drawer:slide",), velocity=True),
    )
    achieved = "handle_pos"
    view = "left"  # level with the handle: the hook behind it shows
    cabinet_x = (1.40, 1.43)
    """[m] the cabinet's centre x: its back stays on the table, the open handle within reach."""
    cabinet_y = 0.10
    """[m] the cabinet's centre y is sampled this far around the gripper's start."""
    firm_furniture = True  # the fingers sank up to 5.2 mm into the drawer under abuse; 0.3 mm now
    start_opening: float
    goal_opening: float

    def build(self, spec: mujoco.MjSpec) -> None:
        add_cabinet(spec)

    def bind(self, model: mujoco.MjModel) -> None:
        self.cabinet_mocap = mocap_index(model, "cabinet")
        joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "drawer:slide")
        self.slide_qpos = int(model.jnt_qposadr[joint])
        self.slide_qvel = int(model.jnt_dofadr[joint])

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              start: Start) -> np.ndarray:
        x = rng.uniform(*self.cabinet_x)
        y = start.grip[1] + rng.uniform(-self.cabinet_y, self.cabinet_y)
        data.mocap_pos[self.cabinet_mocap] = (x, y, TABLE_TOP)
        data.qpos[self.slide_qpos] = self.start_opening
        data.qvel[self.slide_qvel] = 0.0
        return np.array([x + HANDLE_X - self.goal_opening, y, TABLE_TOP + HANDLE_Z])

    def facts(self, data: mujoco.MjData, obs: np.ndarray) -> dict[str, float]:
        return {"drawer_opening": data.qpos.item(self.slide_qpos)}


class DrawerOpen(_DrawerTask):
    """Hook the handle and pull the drawer open by at least 15 cm (goal: the handle fully open)."""

    name = "drawer_open"
    instruction = "open the drawer"
    expert = "fetch.experts.motion:Drawer"
    success_rule = "drawer open by >= 15 cm (the handle within 5 cm of the goal)"
    start_opening = 0.0
    goal_opening = SLIDE
    subtasks = (HOOK, Subtask("pull", "handle", None))


class DrawerClose(_DrawerTask):
    """Push the open drawer shut to at most 5 cm (goal: the handle with the drawer closed)."""

    name = "drawer_close"
    instruction = "close the drawer"
    expert = "fetch.experts.motion:Drawer"
    success_rule = "drawer open by <= 5 cm (the handle within 5 cm of the goal)"
    start_opening = SLIDE
    goal_opening = 0.0
    subtasks = (HOOK, Subtask("push", "handle", None))
