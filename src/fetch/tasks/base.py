"""What a task is (scene additions, observation parts, start and goal sampling, success)."""

from __future__ import annotations

import abc
import math
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import mujoco
import numpy as np

from fetch import observation as ob
from fetch.robot import RobotConfig

if TYPE_CHECKING:
    from fetch.tasks.subtasks import Subtask

TABLE_TOP = 0.4
"""[m] height of the table's surface in every task."""

DISTANCE_THRESHOLD = 0.05
"""[m] the classic success radius."""

GRIP = "robot0:grip"
FINGERS = ("robot0:r_gripper_finger_joint", "robot0:l_gripper_finger_joint")
FINGER_PAIRS = {FINGERS[0]: FINGERS[1], FINGERS[1]: FINGERS[0]}
"""Each finger's mirror image in the hand's plane of symmetry."""

GRIPPER_PARTS: tuple[ob.Part, ...] = (
    ob.site_pos("grip_pos", GRIP),
    ob.joints("gripper_state", FINGERS),
    ob.linvel("grip_velp", GRIP),
    ob.joints("gripper_vel", FINGERS, velocity=True),
)
"""The classic Reach observation: 10 numbers."""


def object_parts(obj: str, site: str) -> tuple[ob.Part, ...]:
    """The classic 25-D object-task observation, with the object called `obj` observed at `site`."""
    return (
        ob.site_pos("grip_pos", GRIP),
        ob.site_pos(f"{obj}_pos", site),
        ob.rel_pos(f"{obj}_rel_pos", site, GRIP),
        ob.joints("gripper_state", FINGERS),
        ob.euler(f"{obj}_rot", site),
        ob.linvel(f"{obj}_velp", site, ref=GRIP),
        ob.angvel(f"{obj}_velr", site),
        ob.linvel("grip_velp", GRIP),
        ob.joints("gripper_vel", FINGERS, velocity=True),
    )


class Start(NamedTuple):
    """What a task's reset samples around, fixed when the scene is compiled."""

    grip: np.ndarray
    """[m] the grip site at the start (the classic suite's `initial_gripper_xpos`)."""
    object_z: float | None
    """[m] the classic object tasks: the object's height at the start (their `height_offset`)."""


class Task(abc.ABC):
    """One manipulation task: what it adds to the scene, how it starts, what success is.

    A task holds no per-episode state: everything randomised at reset is written into MjData
    (qpos, mocap), so a saved MuJoCo state restores the episode exactly.
    """

    name: ClassVar[str]
    instruction: ClassVar[str]
    """the task in one sentence, as a person is told it (LeRobot's `task` string, what a
    language-conditioned policy reads)."""
    expert: ClassVar[str]
    """its scripted expert: "module:callable" (`fetch._references`), called with the observation layout
    (`fetch.experts.make_expert`)."""
    robot: ClassVar[RobotConfig] = RobotConfig()
    parts: ClassVar[tuple[ob.Part, ...]]
    achieved: ClassVar[str]
    """the part that is the achieved goal."""
    success_rule: ClassVar[str] = "within 5 cm of the goal"
    """how success is judged, in words (the README's task table shows it)."""
    subtasks: ClassVar[tuple[Subtask, ...]] = ()
    """the object-centric parts of its demos, in order (`fetch.tasks.subtasks`; demo generation)."""
    mirrors: ClassVar[bool] = False
    """whether the scene and the start are symmetric about the vertical x-z plane through the start's
    grip site, so a demo reflected in it is a demo of the task (`gym-fetch train --mirror`; a test
    checks the scene, the start and the hand's motion of each task that says so)."""
    view: ClassVar[str] = "operator"
    """the camera a person's collection window opens on: the one that shows the task's key contact
    (`fetch.teleop.scenery.VIEWPOINTS`, or one of the scene's cameras)."""
    firm_furniture: ClassVar[bool] = False
    """whether the fingers meet the room's furniture with its stiff contacts (`fetch.scene.firm_furniture`):
    where nothing free can be pinched between the two (bench_abuse.py)."""

    @abc.abstractmethod
    def build(self, spec: mujoco.MjSpec) -> None:
        """Add the task's objects and furniture to the scene."""

    def bind(self, model: mujoco.MjModel) -> None:  # noqa: B027 (optional hook)
        """Resolve names to ids once; later calls index with integers only."""

    @abc.abstractmethod
    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              start: Start) -> np.ndarray:
        """Place objects and furniture in `data` (positions only, at rest) and return the goal [m]."""

    def is_success(self, achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        """1.0 where the goal is reached, else 0.0; vectorised over leading axes (for HER)."""
        return (goal_distance(achieved, desired) < DISTANCE_THRESHOLD).astype(np.float64)

    def success(self, achieved: list[float], desired: list[float], distance: float) -> bool:
        """`is_success` for one goal, given their distance [m], in scalar math (it runs every
        step); a test holds the two equal."""
        return distance < DISTANCE_THRESHOLD

    def facts(self, data: mujoco.MjData, obs: np.ndarray) -> dict[str, float]:
        """Task-specific entries of `info`: the same keys at every step."""
        return {}


REWARD_TYPES = ("sparse", "dense")


def reward(reward_type: str, success: Any, distance: Any) -> Any:
    """The reward of a step (or of many, as arrays) from its success (0 or 1) and its goal distance
    [m]: sparse, 0 where the goal is reached else -1; dense, minus the distance. The one rule of
    `FetchEnv.step`, `FetchEnv.compute_reward` and `FetchVectorEnv.step`."""
    return success - 1.0 if reward_type == "sparse" else -distance


def goal_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[m] Euclidean distance over the last axis."""
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return np.sqrt(np.sum(diff * diff, axis=-1))


class FreeObject:
    """A body on a free joint, placed at reset by writing its qpos."""

    def __init__(self, model: mujoco.MjModel, body: str) -> None:
        body_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
        joint = int(model.body_jntadr[body_id])
        self.qpos = int(model.jnt_qposadr[joint])
        self.qvel = int(model.jnt_dofadr[joint])

    def place(self, data: mujoco.MjData, pos: np.ndarray, yaw: float = 0.0) -> None:
        """Put the body at rest at `pos` [m], rotated by `yaw` [rad] about z."""
        data.qpos[self.qpos:self.qpos + 3] = pos
        data.qpos[self.qpos + 3:self.qpos + 7] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        data.qvel[self.qvel:self.qvel + 6] = 0.0


def mocap_index(model: mujoco.MjModel, body: str) -> int:
    """The index into `data.mocap_pos` of a mocap body."""
    return int(model.body_mocapid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)])


def sample_clear_xy(rng: np.random.Generator, center: np.ndarray, half_range: float | np.ndarray,
                    keep_out: list[tuple[np.ndarray, float]], tries: int = 1000) -> np.ndarray:
    """A uniform xy point in center +- half_range at least r [m] from every (point, r) in keep_out."""
    center = np.asarray(center, dtype=np.float64)[:2]
    for _ in range(tries):
        xy = center + rng.uniform(-half_range, half_range, size=2)
        if all(math.hypot(*(xy - np.asarray(p)[:2])) >= r for p, r in keep_out):
            return xy
    raise RuntimeError(f"no clear spot near {center} after {tries} tries; the task's ranges are inconsistent")


def box_geom(body: mujoco.MjsBody, name: str, half: list[float], pos: list[float],
             material: str, **attrs: object) -> mujoco.MjsGeom:
    """Add a box geom of half-sizes `half` [m] at `pos` [m] in the body's frame."""
    return body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=half, pos=pos,
                         material=material, **attrs)
