"""The Fetch arm: its configuration, cached ids in a compiled model, and how an action moves it (its
scene, built from gymnasium-robotics' asset files, is `fetch.scene`)."""

from __future__ import annotations

import dataclasses
import functools
import math
import struct

import mujoco
import numpy as np

from fetch.timing import N_SUBSTEPS

ACTION_STEP = 0.05
"""[m] how far the hand's target moves along each world axis per step at |a| = 1 (the classic suite)."""

HAND_RESPONSE = 0.64
"""The share of a commanded move (`ACTION_STEP * a[:3]`) the hand covers in one step, free of contact: the
target is put there, the weld pulls the arm towards it for the step's substeps, and the next step moves from
where the hand got to (`Robot.hold`). Measured on every axis and task at 0.63-0.66 once moving, 0.57-0.59 on
the first step from rest (tests/test_generate.py checks it)."""

QUAT_STEP = np.array([1.0, 0.0, 1.0, 0.0])
"""Added to the hand's orientation quaternion each step (MuJoCo normalises the sum), as in the
classic suite: the target orientation is halfway between the hand's and fingers-down."""

GRIPPER_QUAT = QUAT_STEP / np.sqrt(2.0)
"""World orientation of the gripper (w, x, y, z): fingers pointing down, closing along world y."""

CLASSIC_START_OFFSET = np.array([-0.498, 0.005, -0.431])
"""[m] the classic suite's gripper start, relative to the grip site in the robot's zero pose."""

@dataclasses.dataclass(frozen=True)
class Workspace:
    """A box the hand's target is kept in [m, world, the grip site's position]."""

    low: tuple[float, float, float] = (1.0, 0.35, 0.42)
    high: tuple[float, float, float] = (1.6, 1.15, 0.9)

    def __post_init__(self) -> None:
        low, high = np.asarray(self.low), np.asarray(self.high)
        if low.shape != (3,) or high.shape != (3,) or not np.all(low < high):
            raise ValueError(f"workspace low {self.low} must be below high {self.high} on each of x, y, z")


def dart_std(noise: float, finger_noise: float | None) -> np.ndarray:
    """(4,) the std of DART's noise on each action entry: `noise` on the hand's three (action units: 0.1 is
    5 mm of hand target), `finger_noise` on a[3] (metres of finger target; None: `noise`, so 0.1 swings the
    fingers open and shut). The expert device and `generate` perturb their actions with it."""
    finger = noise if finger_noise is None else finger_noise
    return np.array([noise, noise, noise, finger])


def checked_actions(actions: np.ndarray) -> np.ndarray:
    """An action (4,) or a batch of them (N, 4) as a step applies it: real numbers, finite, clipped to
    [-1, 1], in its own precision (float32 stays float32, anything else is float64), as the classic
    suite does: a float32 action moves the target by float32(0.05 * a), a float64 one by the float64
    product. The one check and the one clip between a device and the physics, for `FetchEnv.step` and
    `FetchVectorEnv.step` alike; ValueError naming what is wrong (the rows, for a batch)."""
    a = np.asarray(actions)
    if np.iscomplexobj(a) or a.dtype.kind not in "fiu":
        raise ValueError(f"{'actions' if a.ndim == 2 else 'action'} must be real numbers, got dtype {a.dtype}")
    if a.dtype != np.float32:
        a = a.astype(np.float64)
    if not np.isfinite(a).all():
        if a.ndim == 2:
            bad = np.flatnonzero(~np.isfinite(a).all(axis=1)).tolist()
            raise ValueError(f"actions of worlds {bad} are not finite ({a[bad[0]].tolist()}); a NaN or inf would "
                             "make the simulation unstable (valid: finite values, clipped to [-1, 1])")
        raise ValueError(f"action {a.tolist()} is not finite; a NaN or inf would make the "
                         "simulation unstable (valid: finite values, clipped to [-1, 1])")
    return np.clip(a, -1.0, 1.0)


def checked_action(action: np.ndarray) -> tuple[np.ndarray, list[float], float]:
    """`checked_actions` then `action_rule` for one action (4,): (the clipped action, move [m, world], grip),
    the same numbers. `FetchEnv.step`'s path: for a float32 or float64 action the check and the clip run
    on Python floats, where numpy's calls on four numbers were a quarter of the step's overhead over its
    physics; any other action takes the general path (and its messages)."""
    a = np.asarray(action)
    values = a.tolist() if a.shape == (4,) and a.dtype in _FLOATS else None
    if values is None or not all(map(math.isfinite, values)):
        clipped = checked_actions(a)
        move, grip = action_rule(clipped)
        return clipped, move.tolist(), float(grip)
    if min(values) < -1.0 or max(values) > 1.0:
        values = [min(max(v, -1.0), 1.0) for v in values]  # np.clip's result, float for float
    x, y, z, g = values
    clipped = np.array((x, y, z, g), a.dtype)
    if a.dtype == np.float32:
        # float32 arithmetic, as `action_rule`'s: the product of two float32s is exact in a double, so
        # rounding it to float32 once (packing it) is the float32 product
        return clipped, list(_THREE_FLOAT32.unpack(_THREE_FLOAT32.pack(x * _STEP32, y * _STEP32, z * _STEP32))), g
    return clipped, [x * ACTION_STEP, y * ACTION_STEP, z * ACTION_STEP], g


_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))
_STEP32 = float(np.float32(ACTION_STEP))
_THREE_FLOAT32 = struct.Struct("=3f")


def action_rule(actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(move [m, world], grip) of checked actions, as float64 (the last axis: x, y, z, gripper): the
    target moves by `ACTION_STEP * a[:3]`, computed in the action's precision; the fingers are driven
    by a[3]. `Robot.apply` (one world) and `Robot.apply_batch` (many) take these."""
    return (actions[..., :3] * ACTION_STEP).astype(np.float64), actions[..., 3].astype(np.float64)


@dataclasses.dataclass(frozen=True)
class RobotConfig:
    """Which scene the robot stands in, where, where its gripper starts and how far it may go.

    Positions are world coordinates [m]; the grip site is the point between the fingertips' base.
    """

    scene: str | None = None
    """gymnasium-robotics' task file the classic tasks load as it is (e.g. "push.xml"), or None
    for our room (assets/scene.xml) with the robot in it."""
    base_xy: tuple[float, float] = (0.405, 0.48)
    """our room: where the mobile base is parked (the classic `robot0:slide0/1` values). A classic
    scene's start state, base included, is loaded as recorded."""
    start_height: float = 0.2
    """our room: the classic `gripper_extra_height`: the start target is the classic offset plus this in z."""
    workspace: Workspace | None = Workspace()
    """the box the hand's target is clamped to (teleoperation safety); None: unlimited, as in the
    classic suite."""
    block_gripper: bool = False
    """keep the fingers closed whatever a[3] says (Reach, Push, Slide)."""


class Robot:
    """The Fetch arm in a compiled model: cached ids, its start, and how an action moves it.

    An action moves the hand as the classic suite does: the mocap target is put at the hand's
    pose plus `ACTION_STEP * a[:3]` (per axis) and `QUAT_STEP`, then the physics runs. Between
    steps the mocap body holds that reference pose (`hold`), so it is part of the saved state and
    a restored state steps exactly as the original did.
    """

    def __init__(self, config: RobotConfig, model: mujoco.MjModel) -> None:
        self.config = config
        name = functools.partial(mujoco.mj_name2id, model)
        self.grip_site = name(mujoco.mjtObj.mjOBJ_SITE, "robot0:grip")
        self.hand = name(mujoco.mjtObj.mjOBJ_BODY, "robot0:gripper_link")
        self.mocap = int(model.body_mocapid[name(mujoco.mjtObj.mjOBJ_BODY, "robot0:mocap")])
        fingers = [name(mujoco.mjtObj.mjOBJ_JOINT, f"robot0:{s}_gripper_finger_joint") for s in "rl"]
        # Observation order is the classic one: right finger, then left.
        self.finger_qpos = model.jnt_qposadr[fingers].copy()
        # Each finger actuator with the qpos address of the finger it drives (the classic Reach,
        # Push and Slide have none: their fingers are held shut by resetting them every step).
        self._finger_ctrl_qpos = tuple(
            (act, int(model.jnt_qposadr[model.actuator_trnid[act, 0]]))
            for act in range(model.nu) if int(model.actuator_trnid[act, 0]) in fingers)
        # The mocap body is welded to gripper_link, whose origin sits this far from the grip site.
        self.grip_to_mocap = -_rotate(GRIPPER_QUAT, model.site_pos[self.grip_site])
        self._block_gripper = bool(config.block_gripper)
        self._finger_qpos = tuple(int(i) for i in self.finger_qpos)
        self._box: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        if config.workspace is not None:
            # The box is stated for the grip site; the mocap body sits `grip_to_mocap` from it.
            self._box = (tuple((np.asarray(config.workspace.low) + self.grip_to_mocap).tolist()),
                         tuple((np.asarray(config.workspace.high) + self.grip_to_mocap).tolist()))

    def start_target(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        """[m] where the classic rule puts the mocap body (gripper_link) at the start, from the
        grip site's present position (clamped to the workspace, if any)."""
        target = data.site_xpos[self.grip_site] + CLASSIC_START_OFFSET
        target[2] += self.config.start_height
        if self._box is not None:
            target = np.clip(target, self._box[0], self._box[1])
        return target

    def bind(self, data: mujoco.MjData) -> None:
        """Keep views of `data` for the per-step path (MjData's arrays never move)."""
        self._mocap_pos = data.mocap_pos[self.mocap]
        self._mocap_quat = data.mocap_quat[self.mocap]
        self._hand_pos = data.xpos[self.hand]
        self._hand_quat = data.xquat[self.hand]
        self._ctrl = data.ctrl
        self._qpos = data.qpos

    def hold(self) -> None:
        """Make the hand's pose, as last computed, the reference the next action moves from."""
        self._mocap_pos[:] = self._hand_pos
        self._mocap_quat[:] = self._hand_quat

    def apply(self, move: list[float], grip: float) -> None:
        """Put the target at the reference pose plus `move` [m, world] (within the workspace);
        drive the fingers with `grip` (a[3]). Scalar math on the views kept by `bind`."""
        mx, my, mz = self._mocap_pos.tolist()
        x, y, z = mx + move[0], my + move[1], mz + move[2]
        if self._box is not None:
            (lx, ly, lz), (hx, hy, hz) = self._box
            x, y, z = min(max(x, lx), hx), min(max(y, ly), hy), min(max(z, lz), hz)
        self._mocap_pos[:] = (x, y, z)
        self._mocap_quat += QUAT_STEP
        ctrl, qpos = self._ctrl, self._qpos
        if self._block_gripper:
            for act, _ in self._finger_ctrl_qpos:
                ctrl[act] = 0.0
        else:
            # As in the classic suite: a position servo relative to the current opening,
            # saturated by the actuators' ctrlrange (+1 opens fully, -1 closes).
            for act, adr in self._finger_ctrl_qpos:
                ctrl[act] = qpos.item(adr) + grip

    def apply_batch(self, mocap_pos: np.ndarray, mocap_quat: np.ndarray, ctrl: np.ndarray,
                    qpos: np.ndarray, move: np.ndarray, grip: np.ndarray) -> None:
        """`apply` for many worlds at once (`fetch.vector`): the MjData fields as (worlds, ...) rows,
        written in place; `move` (worlds, 3) [m, world] and `grip` (worlds,) as float64. Element for
        element the same float64 operations as `apply`, so each row ends up bit for bit the same."""
        target = mocap_pos[:, self.mocap] + move
        if self._box is not None:
            target = np.minimum(np.maximum(target, self._box[0]), self._box[1])
        mocap_pos[:, self.mocap] = target
        mocap_quat[:, self.mocap] += QUAT_STEP
        for act, adr in self._finger_ctrl_qpos:
            ctrl[:, act] = 0.0 if self._block_gripper else qpos[:, adr] + grip

    def advance(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Run one control period of physics and leave the state current for the observation.

        The classic suite reads the next reference pose from MjData as `mj_step` leaves it: where
        the hand was at the start of the last physics step (its kinematics run before the
        integration). With a blocked gripper it resets the fingers and calls `mj_forward` first,
        so there the reference is the present pose. Both are kept exactly; the observation is
        always of the present state. (Its `mj_forward` changes nothing the next step reads, so
        `present` does the part the observation needs: the motion stays the same to 1e-15 m.)
        """
        # Sensors only feed the observation: computing them in every physics step cost a fifth of
        # the step. They are off for the steps; `present` computes them from the final state.
        opt = model.opt
        flags = opt.disableflags
        opt.disableflags = flags | _NO_SENSORS
        mujoco.mj_step(model, data, nstep=N_SUBSTEPS)
        opt.disableflags = flags
        if not self._block_gripper:  # the kinematics of the last step's start: integration moves only qpos
            pos, quat = self._hand_pos.copy(), self._hand_quat.copy()
        if self._block_gripper:
            qpos = self._qpos
            for adr in self._finger_qpos:
                qpos[adr] = 0.0
        present(model, data)
        if self._block_gripper:
            self.hold()
        else:
            self._mocap_pos[:] = pos
            self._mocap_quat[:] = quat


def present(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Compute what the observation and renderers read from the present state: positions,
    velocities, cameras and sensors. Not collisions, constraints or forces, which the next
    `mj_step` computes afresh (and `mj_forward` would spend a tenth of a control step on)."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_camlight(model, data)
    mujoco.mj_comVel(model, data)
    mujoco.mj_sensorPos(model, data)
    mujoco.mj_sensorVel(model, data)


_NO_SENSORS = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)


def _rotate(quat: np.ndarray, vec: np.ndarray) -> np.ndarray:
    out = np.zeros(3)
    mujoco.mju_rotVecQuat(out, np.asarray(vec, dtype=np.float64), np.asarray(quat, dtype=np.float64))
    return out
