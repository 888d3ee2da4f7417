"""A task's model, built, compiled and settled at its start once per process, and its hash."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
import pathlib

import mujoco
import numpy as np

from fetch import observation as ob
from fetch.errors import FetchError
from fetch.robot import GRIPPER_QUAT, Robot
from fetch.scene import build_spec, firm_furniture
from fetch.tasks.base import Start, Task
from fetch.timing import N_SUBSTEPS

STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
"""What `get_state` saves: everything `mj_step` reads (qpos, qvel, act, ctrl, mocap, warm start, time)."""

SETTLE_STEPS = 50
"""Control steps the arm is given at construction to settle at its start pose."""


@dataclasses.dataclass(frozen=True)
class Compiled:
    model: mujoco.MjModel
    start_state: np.ndarray
    start: Start
    spec: mujoco.MjSpec


def mjb_hash(model: mujoco.MjModel) -> str:
    buffer = np.empty(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return hashlib.sha256(buffer.tobytes()).hexdigest()


@functools.cache
def portable_hash(task_type: type[Task]) -> str:
    """`mjb_hash` of the task's model compiled again with its asset files handed over by relative
    name (in memory), so that no absolute path ends up in it."""
    spec = compiled_task(task_type).spec.copy()
    assets: dict[str, bytes] = {}
    for kind, directory, items in (("meshes", spec.meshdir, spec.meshes), ("textures", spec.texturedir, spec.textures)):
        for item in items:
            if not item.file:
                continue
            path = pathlib.Path(item.file)
            relative = pathlib.Path(path.name) if path.is_absolute() else path
            source = path if path.is_absolute() else pathlib.Path(directory) / path
            assets[f"{kind}/{relative.as_posix()}"] = source.read_bytes()
            item.file = relative.as_posix()
    spec.meshdir, spec.texturedir = "meshes", "textures"
    spec.modelfiledir = ""  # a scene read from a file resolves relative names against its directory
    spec.assets = assets
    return mjb_hash(spec.compile())


@functools.cache
def compiled_task(task_type: type[Task]) -> Compiled:
    """Build, compile and settle a task's scene once per process; envs copy the result."""
    task = task_type()
    spec = build_spec(task_type.robot)
    task.build(spec)
    if task_type.firm_furniture:
        firm_furniture(spec)
    ob.add_sensors(spec, task_type.parts)
    model = spec.compile()
    data = mujoco.MjData(model)
    robot = Robot(task_type.robot, model)
    robot.bind(data)
    task.bind(model)
    if task_type.robot.scene:
        start = settle_classic(model, data, robot, task)
    else:
        start = settle_room(model, data, robot)
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    return Compiled(model, state, start, spec)


CLASSIC_STARTS = pathlib.Path(__file__).parent / "assets" / "classic_starts.npz"
"""The start state of each classic scene as gymnasium-robotics' Fetch*-v4 computes it on mujoco 3.11
(`python -m tools.classic_starts` writes it, in the mujoco 3.11 virtualenv: tools/classic_starts.py)."""


def settle_classic(model: mujoco.MjModel, data: mujoco.MjData, robot: Robot, task: Task) -> Start:
    """The classic suite's start state, as that suite computes it when an env is made: the base and
    object parked by `initial_qpos`, then the hand pulled to its start for 10 control steps, the
    state reached kept, velocities included. It is loaded, not simulated again: on other mujoco
    versions those 10 steps (the base resting on the floor, the torso below its joint limit) end
    up to 0.3 mm elsewhere, and the classic start is the one that its seeds' goals were drawn around."""
    scene = str(task.robot.scene)
    with np.load(CLASSIC_STARTS) as starts:
        qpos, qvel = starts[f"{scene}/qpos"], starts[f"{scene}/qvel"]
        time, grip = float(starts[f"{scene}/time"]), starts[f"{scene}/grip"]
        object_z = float(starts[f"{scene}/object_z"])
    if qpos.shape != (model.nq,) or qvel.shape != (model.nv,):
        raise FetchError(f"{CLASSIC_STARTS.name} holds a {scene} start of {qpos.size} qpos / {qvel.size} qvel; "
                         f"the model has {model.nq} / {model.nv} (a different gymnasium-robotics?)")
    data.time, data.qpos[:], data.qvel[:] = time, qpos, qvel
    mujoco.mj_forward(model, data)
    robot.hold()
    return Start(grip.copy(), None if math.isnan(object_z) else object_z)


def settle_room(model: mujoco.MjModel, data: mujoco.MjData, robot: Robot) -> Start:
    """Our tasks' start: the hand pulled to its start for 50 control steps, then everything at rest."""
    mujoco.mj_forward(model, data)
    data.mocap_pos[robot.mocap] = robot.start_target(model, data)
    data.mocap_quat[robot.mocap] = GRIPPER_QUAT
    for _ in range(SETTLE_STEPS):
        mujoco.mj_step(model, data, nstep=N_SUBSTEPS)
    data.qvel[:] = 0.0
    data.time = 0.0
    mujoco.mj_forward(model, data)
    robot.hold()
    return Start(data.site_xpos[robot.grip_site].copy(), None)
