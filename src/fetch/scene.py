"""The scene the robot stands in, as an `MjSpec`: gymnasium-robotics' own task file for the classic tasks,
our room (assets/scene.xml) with the robot parked in it for the others; plus the cameras and the
contact parameters of the room."""

from __future__ import annotations

import functools
import importlib.util
import pathlib

import mujoco
import numpy as np

from fetch.errors import FetchError
from fetch.robot import RobotConfig
from fetch.timing import PHYSICS_DT

# Joints the classic model carries but never moves (a base on slides damped by 1e11, a torso
# lift damped by 1e7, a head). Removing them makes a step 1.5x faster and changes no behaviour.
_DEAD_JOINTS = (
    "robot0:slide0",
    "robot0:slide1",
    "robot0:slide2",
    "robot0:torso_lift_joint",
    "robot0:head_pan_joint",
    "robot0:head_tilt_joint",
)
# Links that stay >= 0.3 m above the table inside the workspace box: their meshes never
# touch anything, so they are left out of collision detection.
_HIGH_LINKS = (
    "robot0:shoulder_pan_link",
    "robot0:shoulder_lift_link",
    "robot0:upperarm_roll_link",
    "robot0:elbow_flex_link",
)
# The torso, head and base fittings: never near the table, but their meshes overlap each other's
# bounding boxes, so collision detection tested them every physics step for nothing.
_IDLE_LINKS = (
    "robot0:torso_lift_link",
    "robot0:head_pan_link",
    "robot0:head_tilt_link",
    "robot0:estop_link",
    "robot0:laser_link",
    "robot0:torso_fixed_link",
)
_BASE_LINK_OFFSET = np.array([0.2869, 0.2641, 0.0])  # base_link's pos in robot.xml


@functools.cache
def robot_asset_dir() -> pathlib.Path:
    """The directory of gymnasium-robotics' assets, found without importing the package."""
    spec = importlib.util.find_spec("gymnasium_robotics")
    if spec is None or spec.origin is None:
        raise FetchError(
            "gymnasium-robotics is not installed; it provides the Fetch robot's model files "
            "(pip install gymnasium-robotics)"
        )
    root = pathlib.Path(spec.origin).parent / "envs" / "assets"
    for needed in ("fetch/robot.xml", "fetch/shared.xml", "stls/fetch"):
        if not (root / needed).exists():
            raise FetchError(f"gymnasium-robotics at {root.parent.parent} lacks assets/{needed}")
    return root


SCENE_XML = pathlib.Path(__file__).parent / "assets" / "scene.xml"
GOAL_GROUP = 2
"""Geom group holding only the goal marker; renderers turn it off to hide the marker."""

ROOM_SOLREF = (2 * PHYSICS_DT, 1.0)
"""Contacts in our room (floor, table, furniture, objects; the robot's own geoms keep theirs): a
time constant of two physics steps, the stiffest MuJoCo integrates stably (its default: 0.02 s).
With the default, a block the hand drives into the table or a bin wall sank up to 37 mm into it;
with these, <= 5 mm (benchmarks/bench_abuse.py, docs/results/bench_abuse.md)."""
ROOM_SOLIMP = (0.99, 0.999, 0.001, 0.5, 2.0)
"""... and an impedance near 1 at any depth (MuJoCo's default: 0.9 to 0.95), so they barely yield."""
MUJOCO_SOLREF, MUJOCO_SOLIMP = (0.02, 1.0), (0.9, 0.95, 0.001, 0.5, 2.0)
"""MuJoCo's default contact parameters: what the room's geoms had before ROOM_SOLREF, and what the
Box tasks' lid keeps."""
FURNITURE_SOLMIX = 1000.0
"""The weight of furniture's contact parameters against the robot's where the two touch, in tasks
that ask for it (`Task.firm_furniture`). MuJoCo averages a contact's solref and solimp by the geoms'
solmix, and the robot's geoms keep their own softer ones with weight 1: so a finger driven into
the room meets a half-soft contact. Furniture is what neither belongs to the robot nor moves
freely (floor, table, cabinet, drawer; bins and box too). Under bench_abuse.py's 10,000 random
full-scale steps the fingers sank up to 5.2 mm into a drawer with the even mix and 0.3 mm with
this. Not where something free can be pinched between the fingers and furniture: against a stiff
bin wall a block shot out at up to 2.1 m/s instead of 0.9, and sank 6.7 mm into the fingers."""


def build_spec(config: RobotConfig) -> mujoco.MjSpec:
    """The robot in its scene (table, cameras, goal marker), ready for a task's additions."""
    spec = _classic_spec(config) if config.scene else _room_spec(config)
    if hasattr(mujoco.mjtEnableBit, "mjENBL_MULTICCD"):
        # Where several contacts between convex shapes are opt-in (mujoco 3.3; 3.11, where v4 runs,
        # and 4.x give them by default), one contact lets a cylinder on the table rock and sink ~7 mm.
        spec.option.enableflags |= int(mujoco.mjtEnableBit.mjENBL_MULTICCD)
    # The weld holds gripper_link centred on the mocap body, with the same orientation: what the
    # classic suite's reset_mocap_welds sets (the relative pose otherwise defaults to qpos0's).
    weld = spec.equalities[0]
    weld.data[3:10] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    # The mocap body's crosshair geoms are a debugging aid; group 4 is not rendered by default.
    for geom in spec.body("robot0:mocap").geoms:
        geom.group = 4
    for name, pos in CAMERAS.items():
        spec.worldbody.add_camera(name=name, pos=pos, fovy=45.0, quat=look_at(pos, CAMERA_TARGET))
    # In gripper_link's frame +x points down the fingers and -x is world up: the wrist camera
    # sits 6 cm above and 9 cm behind the palm and looks past the fingertips.
    spec.body("robot0:gripper_link").add_camera(
        name="wrist", pos=[-0.06, 0.0, -0.09], fovy=70.0,
        quat=look_at((-0.06, 0.0, -0.09), (0.06, 0.0, 0.05), up=(-1.0, 0.0, 0.0)))
    return spec


def _room_spec(config: RobotConfig) -> mujoco.MjSpec:
    """Our room (floor, table, lights, goal marker) with the robot parked at `config.base_xy`."""
    assets = robot_asset_dir()
    root = f"""<mujoco model="fetch">
  <compiler angle="radian" meshdir="{assets / 'stls' / 'fetch'}" texturedir="{assets / 'textures'}"/>
  <option timestep="{PHYSICS_DT}"/>
  <default><geom solref="{_xml(ROOM_SOLREF)}" solimp="{_xml(ROOM_SOLIMP)}"/></default>
  <include file="{assets / 'fetch' / 'shared.xml'}"/>
  <include file="{SCENE_XML}"/>
  <worldbody><include file="{assets / 'fetch' / 'robot.xml'}"/></worldbody>
</mujoco>"""
    spec = mujoco.MjSpec.from_string(root)
    # Elliptic friction cones: with MuJoCo's default pyramidal ones, sliding friction depends on
    # the direction of motion and an object sliding diagonally curves away from its line.
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    for name in _DEAD_JOINTS:
        _delete(spec, spec.joint(name))
    spec.body("robot0:base_link").pos = np.array([*config.base_xy, 0.0]) + _BASE_LINK_OFFSET
    _out_of_collisions(spec, _HIGH_LINKS)
    # gymnasium-robotics' near-white table saturates under the lights; a light grey keeps texture.
    spec.material("table_mat").rgba = [0.72, 0.72, 0.70, 1.0]
    return spec


def firm_furniture(spec: mujoco.MjSpec) -> None:
    """Give the room's furniture the say in its contacts with the robot (`FURNITURE_SOLMIX`); call
    it once the task has added its bodies."""
    free = {body.name for body in spec.bodies
            if any(joint.type == mujoco.mjtJoint.mjJNT_FREE for joint in body.joints)}
    for body in spec.bodies:
        if body.name.startswith("robot0:") or _under(body, free):
            continue
        for geom in body.geoms:
            geom.solmix = FURNITURE_SOLMIX


def _under(body: mujoco.MjsBody, names: set[str]) -> bool:
    """Whether `body` or one of its ancestors is named in `names`."""
    while body is not None and body.name != "world":
        if body.name in names:
            return True
        body = body.parent
    return False


def _classic_spec(config: RobotConfig) -> mujoco.MjSpec:
    """A classic task's scene exactly as gymnasium-robotics ships it (robot, table, object, options,
    actuators), plus our goal marker. One edit makes it faster without changing the motion
    (parity_v4.py measures it): links that never touch anything are left out of collision
    detection. The joints that never move stay: the base's contact with the floor and the torso's
    start below its joint limit move the hand by up to 0.6 mm during the start, and the classic
    start is kept exactly."""
    assets = robot_asset_dir()
    spec = mujoco.MjSpec.from_file(str(assets / "fetch" / str(config.scene)))
    if spec.option.timestep != PHYSICS_DT:
        raise FetchError(f"{config.scene} steps physics by {spec.option.timestep} s; the suite's control "
                         f"period assumes {PHYSICS_DT} s (a different gymnasium-robotics?)")
    # Absolute asset paths, so the model's XML (stored in datasets) compiles from anywhere.
    spec.meshdir = str(assets / "stls" / "fetch")
    spec.texturedir = str(assets / "textures")
    _out_of_collisions(spec, _HIGH_LINKS + _IDLE_LINKS)
    # Their goal marker is a site they move by editing the model; ours is a mocap body, so the goal
    # is part of the saved state. Group 2 holds the marker alone (renderers hide it by that group).
    _delete(spec, spec.site("target0"))
    goal = spec.worldbody.add_body(name="goal", mocap=True, pos=[1.3, 0.75, 0.6])
    goal.add_geom(name="goal", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02, 0, 0], rgba=[1, 0, 0, 0.6],
                  group=GOAL_GROUP, contype=0, conaffinity=0, mass=0.001)
    spec.visual.global_.offwidth = 640
    spec.visual.global_.offheight = 480
    return spec


def _xml(values: tuple[float, ...]) -> str:
    return " ".join(repr(v) for v in values)


def _out_of_collisions(spec: mujoco.MjSpec, names: tuple[str, ...]) -> None:
    """Leave the named geoms out of collision detection (links that never touch anything)."""
    for geom in spec.geoms:
        if geom.name in names:
            geom.contype = 0
            geom.conaffinity = 0


def _delete(spec: mujoco.MjSpec, element: object) -> None:
    """Remove an element from a spec: `MjSpec.delete` from mujoco 3.3.1, `element.delete` before."""
    if hasattr(spec, "delete"):
        spec.delete(element)
    else:
        element.delete()  # type: ignore[attr-defined]


CAMERA_TARGET = (1.3, 0.75, 0.45)
CAMERAS = {
    "front": (2.15, 0.75, 1.0),  # across the table, facing the robot
    "side": (1.3, -0.15, 0.95),  # from the robot's right
    "behind": (0.55, 0.75, 2.0),  # over the robot's head: the operator's view
}
"""[m] the world cameras' positions; each looks at CAMERA_TARGET. `wrist` rides on the gripper."""


def look_at(pos: tuple[float, float, float], target: tuple[float, float, float],
            up: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """The quaternion of a camera at `pos` looking at `target`, the image's up towards `up`."""
    forward = np.subtract(target, pos)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    return _axes_quat(right, np.cross(right, forward))


def _axes_quat(x: object, y: object) -> np.ndarray:
    """A camera's orientation as a quaternion, from its x (right) and y (up) axes in the parent frame."""
    xa, ya = np.asarray(x, float), np.asarray(y, float)
    mat = np.column_stack([xa, ya, np.cross(xa, ya)])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat.flatten())
    return quat
