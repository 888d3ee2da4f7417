"""The Fetch arm: its model from gymnasium-robotics' asset files, cached ids, and how an action moves it."""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import math
import pathlib

import mujoco
import numpy as np

from fetch.errors import FetchError

ACTION_STEP = 0.05
"""[m] the mocap target moves per step at |a| = 1 (as in the classic suite)."""

GRIPPER_QUAT = np.array([1.0, 0.0, 1.0, 0.0]) / np.sqrt(2.0)
"""World orientation of the gripper (w, x, y, z): fingers pointing down, closing along world y."""

N_SUBSTEPS = 20
"""Physics steps of 2 ms per control step: dt = 0.04 s, 25 Hz, as in the classic suite."""

CLASSIC_START_OFFSET = np.array([-0.498, 0.005, -0.431])
"""[m] the classic suite's gripper start, relative to the grip site in the robot's zero pose."""

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


@dataclasses.dataclass(frozen=True)
class RobotConfig:
    """Where the robot stands, where its gripper starts and how far it may go.

    Positions are world coordinates [m]; the grip site is the point between the fingertips' base.
    """

    base_xy: tuple[float, float] = (0.405, 0.48)
    """the classic `robot0:slide0/1` values: where the mobile base is parked."""
    start_height: float = 0.2
    """the classic `gripper_extra_height`: the start target is the classic offset plus this in z."""
    start_shift_x: float = 0.0
    """[m] added to the classic start's x: with `base_xy` moved by the opposite amount, the hand
    starts at the same place in the room while the arm reaches further."""
    workspace_low: tuple[float, float, float] = (1.0, 0.35, 0.42)
    workspace_high: tuple[float, float, float] = (1.6, 1.15, 0.9)
    max_lead: float = 0.05
    """[m] how far the mocap target may be ahead of the grip site."""
    block_gripper: bool = False
    """keep the fingers closed whatever a[3] says (Reach, Push, Slide)."""

    def __post_init__(self) -> None:
        low, high = np.asarray(self.workspace_low), np.asarray(self.workspace_high)
        if low.shape != (3,) or high.shape != (3,) or not np.all(low < high):
            raise ValueError(f"workspace_low {self.workspace_low} must be below workspace_high "
                             f"{self.workspace_high} on each of x, y, z")
        if not 0.0 < self.max_lead <= 0.2:
            raise ValueError(f"max_lead must be in (0, 0.2] m, got {self.max_lead}")


def build_spec(config: RobotConfig) -> mujoco.MjSpec:
    """The robot in the room (floor, table, cameras, goal marker), ready for a task's additions."""
    assets = robot_asset_dir()
    root = f"""<mujoco model="fetch">
  <compiler angle="radian" meshdir="{assets / 'stls' / 'fetch'}" texturedir="{assets / 'textures'}"/>
  <option timestep="0.002"/>
  <include file="{assets / 'fetch' / 'shared.xml'}"/>
  <include file="{SCENE_XML}"/>
  <worldbody><include file="{assets / 'fetch' / 'robot.xml'}"/></worldbody>
</mujoco>"""
    spec = mujoco.MjSpec.from_string(root)
    # Elliptic friction cones: with MuJoCo's default pyramidal ones, sliding friction depends on
    # the direction of motion and a puck gliding diagonally curves away from its line.
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    if hasattr(mujoco.mjtEnableBit, "mjENBL_MULTICCD"):
        # Before mujoco 4 convex-convex collisions give one contact unless asked for more: a
        # cylinder on the table then rocks and sinks ~7 mm. 4.x does this by default.
        spec.option.enableflags |= int(mujoco.mjtEnableBit.mjENBL_MULTICCD)
    for name in _DEAD_JOINTS:
        _delete(spec, spec.joint(name))
    base = spec.body("robot0:base_link")
    base.pos = np.array([*config.base_xy, 0.0]) + _BASE_LINK_OFFSET
    for geom in spec.geoms:
        if geom.name in _HIGH_LINKS:
            geom.contype = 0
            geom.conaffinity = 0
    # The weld's relative pose defaults to the one in qpos0 (mocap at the origin); the
    # controller wants the gripper centred on the mocap body.
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
    # gymnasium-robotics' near-white table saturates under the lights; a light grey keeps texture.
    spec.material("table_mat").rgba = [0.72, 0.72, 0.70, 1.0]
    return spec


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


class Robot:
    """The Fetch arm in a compiled model: cached ids, start, action and proprioception."""

    def __init__(self, config: RobotConfig, model: mujoco.MjModel) -> None:
        self.config = config
        self.low = np.asarray(config.workspace_low, dtype=np.float64)
        self.high = np.asarray(config.workspace_high, dtype=np.float64)
        name = functools.partial(mujoco.mj_name2id, model)
        self.grip_site = name(mujoco.mjtObj.mjOBJ_SITE, "robot0:grip")
        self.mocap = int(model.body_mocapid[name(mujoco.mjtObj.mjOBJ_BODY, "robot0:mocap")])
        fingers = [name(mujoco.mjtObj.mjOBJ_JOINT, f"robot0:{s}_gripper_finger_joint") for s in "rl"]
        # Observation order is the classic one: right finger, then left.
        self.finger_qpos = model.jnt_qposadr[fingers].copy()
        self.finger_ctrl = np.array([
            name(mujoco.mjtObj.mjOBJ_ACTUATOR, f"robot0:{s}_gripper_finger_joint") for s in "lr"
        ])
        # The mocap body is welded to gripper_link, whose origin sits this far from the grip site.
        self.grip_to_mocap = -_rotate(GRIPPER_QUAT, model.site_pos[self.grip_site])
        # Plain Python copies for the per-step scalar math.
        self._max_lead, self._block_gripper = float(config.max_lead), bool(config.block_gripper)
        self._offset = tuple(self.grip_to_mocap.tolist())
        self._low, self._high = tuple(self.low.tolist()), tuple(self.high.tolist())
        self._finger_qpos = tuple(int(i) for i in self.finger_qpos)
        self._finger_ctrl = tuple(int(i) for i in self.finger_ctrl)
        # Each actuator (l, r) with the qpos address of the finger it drives.
        self._finger_ctrl_qpos = tuple(zip(self._finger_ctrl, self._finger_qpos[::-1], strict=True))

    def start_target(self, model: mujoco.MjModel) -> np.ndarray:
        """[m] the grip site's start target: the classic rule, clamped to the workspace.

        The classic suite puts the mocap body (gripper_link), not the grip site, at the offset.
        """
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        target = data.site_xpos[self.grip_site] + CLASSIC_START_OFFSET - self.grip_to_mocap
        target[0] += self.config.start_shift_x
        target[2] += self.config.start_height
        return np.clip(target, self.low, self.high)

    def set_target(self, data: mujoco.MjData, target: np.ndarray) -> None:
        """Place the mocap target so the grip site is pulled to `target` [m, world]."""
        data.mocap_pos[self.mocap] = target + self.grip_to_mocap
        data.mocap_quat[self.mocap] = GRIPPER_QUAT

    def target(self, data: mujoco.MjData) -> np.ndarray:
        """[m] where the grip site is being pulled to."""
        return data.mocap_pos[self.mocap] - self.grip_to_mocap

    def bind(self, data: mujoco.MjData) -> None:
        """Keep views of `data` for the per-step path (MjData's arrays never move)."""
        self._grip = data.site_xpos[self.grip_site]
        self._mocap_pos = data.mocap_pos[self.mocap]
        self._ctrl = data.ctrl
        self._qpos = data.qpos

    def apply(self, action: list[float]) -> None:
        """Move the target by action[:3] * 5 cm within the limits; drive the fingers with action[3].

        The target is clamped to `max_lead` from the grip site, then to the workspace box, so
        a held stick cannot wind it up far from the hand. Scalar math on the views kept by
        `bind`: this runs every step.
        """
        a0, a1, a2, a3 = action
        gx, gy, gz = self._grip.tolist()
        ox, oy, oz = self._offset
        mx, my, mz = self._mocap_pos.tolist()
        dx = mx - ox + ACTION_STEP * a0 - gx
        dy = my - oy + ACTION_STEP * a1 - gy
        dz = mz - oz + ACTION_STEP * a2 - gz
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        if dist > self._max_lead:
            scale = self._max_lead / dist
            dx, dy, dz = dx * scale, dy * scale, dz * scale
        (lx, ly, lz), (hx, hy, hz) = self._low, self._high
        self._mocap_pos[:] = (
            min(max(gx + dx, lx), hx) + ox,
            min(max(gy + dy, ly), hy) + oy,
            min(max(gz + dz, lz), hz) + oz,
        )
        ctrl, qpos = self._ctrl, self._qpos
        if self._block_gripper:
            for act in self._finger_ctrl:
                ctrl[act] = 0.0
        else:
            # As in the classic suite: a position servo relative to the current opening,
            # saturated by the actuators' ctrlrange (+1 opens fully, -1 closes).
            for act, adr in self._finger_ctrl_qpos:
                ctrl[act] = qpos.item(adr) + a3


def _rotate(quat: np.ndarray, vec: np.ndarray) -> np.ndarray:
    out = np.zeros(3)
    mujoco.mju_rotVecQuat(out, np.asarray(vec, dtype=np.float64), np.asarray(quat, dtype=np.float64))
    return out
