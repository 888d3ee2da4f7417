"""Object-centric subtasks: what a task's demos are made of, and when each part is over.

A task declares its subtasks in order (`Task.subtasks`). Each names the frame its motion is
relative to (an object's site, or the goal) and a termination signal computed from `MjData`
alone, so any demo (a person's, an expert's, a generated one) can be cut into segments from its
saved states with no one marking it. The last subtask ends with the demo (its signal is None).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple, Protocol

import mujoco
import numpy as np

GOAL = "goal"
"""The reference that means the episode's goal (the goal marker's mocap position)."""
FINGERS = ("robot0:r_gripper_finger_link", "robot0:l_gripper_finger_link")
GRIP = "robot0:grip"


class Frame(NamedTuple):
    """Where a subtask's motion is anchored: a point [m, world] and a heading about z [rad]."""

    pos: np.ndarray
    yaw: float


class Scene:
    """Ids resolved once for the signals and frames of one compiled model."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.grip = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, GRIP)
        self.fingers = tuple(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f) for f in FINGERS)
        goal_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "goal")
        self.goal_mocap = int(model.body_mocapid[goal_body])
        self._sites: dict[str, int] = {}
        self._bodies: dict[str, int] = {}

    def site(self, name: str) -> int:
        if name not in self._sites:
            found = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, name)
            if found < 0:
                raise ValueError(f"the model has no site {name!r}")
            self._sites[name] = found
        return self._sites[name]

    def body(self, name: str) -> int:
        if name not in self._bodies:
            found = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
            if found < 0:
                raise ValueError(f"the model has no body {name!r}")
            self._bodies[name] = found
        return self._bodies[name]

    def point(self, data: mujoco.MjData, name: str) -> np.ndarray:
        """[m] a site's position, or the goal's for `GOAL` (a copy)."""
        if name == GOAL:
            return data.mocap_pos[self.goal_mocap].copy()
        return data.site_xpos[self.site(name)].copy()

    def grip_pos(self, data: mujoco.MjData) -> np.ndarray:
        return data.site_xpos[self.grip].copy()

    def loose(self, site: str) -> tuple[float, float] | None:
        """[m] the extent of the body that carries `site` around it, if that body is loose (a free
        joint: a block, a lid, what the hand can drag or knock over): its radius in xy and its height
        above the site, upright; None for fixed or jointed parts (a drawer, a cabinet) and the goal."""
        if site == GOAL:
            return None
        m = self.model
        body = int(m.site_bodyid[self.site(site)])
        if m.body_jntnum[body] != 1 or m.jnt_type[int(m.body_jntadr[body])] != mujoco.mjtJoint.mjJNT_FREE:
            return None
        geoms = np.flatnonzero(m.geom_bodyid == body)
        offset = m.geom_pos[geoms] + m.geom_aabb[geoms, :3] - m.site_pos[self.site(site)]
        half = m.geom_aabb[geoms, 3:]
        radius = np.linalg.norm(offset[:, :2], axis=1) + np.linalg.norm(half[:, :2], axis=1)
        return float(radius.max(initial=0.0)), float((offset[:, 2] + half[:, 2]).max(initial=0.0))

    def touching(self, data: mujoco.MjData, body: str) -> tuple[bool, bool]:
        """Whether each finger (right, left) is in contact with a geom of `body`."""
        target = self.body(body)
        n = data.ncon
        if n == 0:
            return False, False
        bodies = self.model.geom_bodyid
        b1, b2 = bodies[data.contact.geom1[:n]], bodies[data.contact.geom2[:n]]
        touching = []
        for finger in self.fingers:
            pair = ((b1 == finger) & (b2 == target)) | ((b2 == finger) & (b1 == target))
            touching.append(bool(pair.any()))
        return touching[0], touching[1]


class Signal(Protocol):
    """A subtask's termination signal: true from the state at which the subtask is done."""

    def __call__(self, scene: Scene, data: mujoco.MjData) -> bool: ...


@dataclasses.dataclass(frozen=True)
class Grasped:
    """Both fingers touch the object's body (the grasp has closed on it)."""

    body: str

    def __call__(self, scene: Scene, data: mujoco.MjData) -> bool:
        right, left = scene.touching(data, self.body)
        return right and left


@dataclasses.dataclass(frozen=True)
class Lifted:
    """The object is grasped and its site is at least `z` [m, world] high (clear of walls or rims)."""

    body: str
    site: str
    z: float

    def __call__(self, scene: Scene, data: mujoco.MjData) -> bool:
        return scene.point(data, self.site)[2] >= self.z and Grasped(self.body)(scene, data)


@dataclasses.dataclass(frozen=True)
class Hooked:
    """The grip site is in the slot behind a handle bar: `behind` [m] past the handle's site along
    +x, within `tolerance` (x, y, z) [m] of that point."""

    site: str
    behind: float
    tolerance: tuple[float, float, float]

    def __call__(self, scene: Scene, data: mujoco.MjData) -> bool:
        d = scene.grip_pos(data) - scene.point(data, self.site)
        d[0] -= self.behind
        return bool(np.all(np.abs(d) < self.tolerance))


@dataclasses.dataclass(frozen=True)
class Beside:
    """The grip site is level with the object's site (within `dz` [m]) and within `reach` [m] of it
    in xy: in place to push it."""

    site: str
    dz: float = 0.015
    reach: float = 0.08

    def __call__(self, scene: Scene, data: mujoco.MjData) -> bool:
        d = scene.grip_pos(data) - scene.point(data, self.site)
        return abs(d[2]) < self.dz and math.hypot(d[0], d[1]) < self.reach


@dataclasses.dataclass(frozen=True)
class Subtask:
    """One object-centric part of a task's demos."""

    name: str
    reference: str
    """the site whose position anchors this part's motion, or `GOAL`."""
    done: Signal | None
    """true from the state at which this part is over; None: it lasts to the demo's end (the last part)."""
    heading: str | None = None
    """None: the frame keeps the world's axes; a site or `GOAL`: its x axis points from the reference
    towards that point (Push and Slide: the line from the object to the goal)."""

    def frame(self, scene: Scene, data: mujoco.MjData) -> Frame:
        pos = scene.point(data, self.reference)
        yaw = 0.0
        if self.heading is not None:
            to = scene.point(data, self.heading) - pos
            yaw = math.atan2(to[1], to[0])
        return Frame(pos, yaw)


class Tracker:
    """Follows a demo step by step: which subtask each step belongs to.

    `step(data)` after each env step (data: the state after it) returns the step's subtask index;
    a subtask ends with the first step after which its signal holds, and the next begins.
    """

    def __init__(self, subtasks: tuple[Subtask, ...], scene: Scene) -> None:
        if not subtasks:
            raise ValueError("a task with no subtasks cannot be segmented")
        self.subtasks = subtasks
        self.scene = scene
        self.current = 0

    def reset(self) -> None:
        self.current = 0

    def step(self, data: mujoco.MjData) -> int:
        k = self.current
        signal = self.subtasks[k].done
        if signal is not None and k < len(self.subtasks) - 1 and signal(self.scene, data):
            self.current = k + 1
        return k

    @property
    def complete(self) -> bool:
        """Every subtask but the last has ended (the demo holds a segment of each)."""
        return self.current == len(self.subtasks) - 1
