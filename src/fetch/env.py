"""The Gymnasium env: one Fetch robot composed with one task."""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import math
import pathlib
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple, SupportsFloat

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.error import ResetNeeded

from fetch import camera_obs, rendering
from fetch import observation as ob
from fetch.errors import FetchError, UnknownNameError
from fetch.robot import GRIPPER_QUAT, Robot, action_rule, checked_actions
from fetch.scene import build_spec, firm_furniture
from fetch.tasks import mirroring_ids, task_class
from fetch.tasks.base import FINGER_PAIRS, REWARD_TYPES, Start, Task, goal_distance, mocap_index
from fetch.tasks.base import reward as task_reward
from fetch.timing import CONTROL_DT, N_SUBSTEPS

STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
"""What `get_state` saves: everything `mj_step` reads (qpos, qvel, act, ctrl, mocap, warm start, time)."""

RENDER_MODES = ("human", "rgb_array", "depth_array")
SETTLE_STEPS = 50
"""Control steps the arm is given at construction to settle at its start pose."""


@dataclasses.dataclass(frozen=True)
class _Compiled:
    model: mujoco.MjModel
    start_state: np.ndarray
    start: Start
    spec: mujoco.MjSpec


def _mjb_hash(model: mujoco.MjModel) -> str:
    buffer = np.empty(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return hashlib.sha256(buffer.tobytes()).hexdigest()


@functools.cache
def _portable_hash(task_type: type[Task]) -> str:
    """`_mjb_hash` of the task's model compiled again with its asset files handed over by relative
    name (in memory), so that no absolute path ends up in it."""
    spec = _compile(task_type).spec.copy()
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
    return _mjb_hash(spec.compile())


@functools.cache
def _compile(task_type: type[Task]) -> _Compiled:
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
        start = _settle_classic(model, data, robot, task)
    else:
        start = _settle_room(model, data, robot)
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    return _Compiled(model, state, start, spec)


CLASSIC_STARTS = pathlib.Path(__file__).parent / "assets" / "classic_starts.npz"
"""The start state of each classic scene as gymnasium-robotics' Fetch*-v4 computes it on mujoco 3.11
(`python -m tools.classic_starts` writes it, in the mujoco 3.11 virtualenv: tools/classic_starts.py)."""


def _settle_classic(model: mujoco.MjModel, data: mujoco.MjData, robot: Robot, task: Task) -> Start:
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


def _settle_room(model: mujoco.MjModel, data: mujoco.MjData, robot: Robot) -> Start:
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


class Reflection(NamedTuple):
    """A task's reflection (`FetchEnv.reflection`): of its observation vector, of its goals, and the
    sign that each action component takes (the hand's y move flips; the fingers do not)."""

    observation: ob.Mirror
    goal: ob.Mirror
    action_sign: np.ndarray


class FetchEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """A goal-conditioned Fetch manipulation env (Gymnasium API, observations as a Dict).

    Action: Box(-1, 1, (4,)): dx, dy, dz move the gripper's target by up to 5 cm per step
    (world frame); a[3] opens (+1) or closes (-1) the fingers. dt = 0.04 s.
    `model`, `data` are the MjModel / MjData; `observation_layout` names the observation's slices.
    `cameras` adds each camera's `image_size` x `image_size` uint8 RGB image of the observed state to the
    observation, as "<camera>_image" (camera_obs.py; `hide_goal` hides the marker there too), drawn at
    `image_quality` (`rendering.IMAGE_QUALITIES`: "fast", the default, or "full").
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": round(1.0 / CONTROL_DT)}

    def __init__(self, task: str = "pick_place", reward_type: str = "sparse",
                 render_mode: str | None = None, width: int = 480, height: int = 480,
                 camera_name: str = "front", hide_goal: bool = False, cameras: Sequence[str] = (),
                 image_size: int = camera_obs.DEFAULT_IMAGE_SIZE,
                 image_quality: str = rendering.DEFAULT_IMAGE_QUALITY) -> None:
        if reward_type not in REWARD_TYPES:
            raise UnknownNameError("reward_type", reward_type, REWARD_TYPES)
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise UnknownNameError("render_mode", render_mode, RENDER_MODES)
        if int(width) <= 0 or int(height) <= 0:
            raise FetchError(f"width and height must be positive pixels, got {width}x{height}")
        self._kwargs = dict(task=task, reward_type=reward_type, render_mode=render_mode,
                            width=int(width), height=int(height), camera_name=camera_name,
                            hide_goal=hide_goal, cameras=cameras, image_size=image_size,
                            image_quality=image_quality)
        compiled = _compile(task_class(task))
        self.task: Task = task_class(task)()
        self.model: mujoco.MjModel = copy.copy(compiled.model)
        self.data = mujoco.MjData(self.model)
        self.robot = Robot(self.task.robot, self.model)
        self.robot.bind(self.data)
        self.task.bind(self.model)
        self._compiled = compiled
        self._start_state = compiled.start_state
        self._start = compiled.start
        rendering.check_camera(self.model, camera_name)
        names = camera_obs.check_cameras(self.model, cameras, image_size)
        rendering.check_image_quality(image_quality, "image_quality")
        self._images = (camera_obs.CameraImages(self.model, names, int(image_size), hide_goal, image_quality)
                        if names else None)
        self.reward_type = reward_type
        self.render_mode = render_mode
        self.width, self.height = int(width), int(height)
        self.camera_name, self.hide_goal = camera_name, hide_goal
        self._renderer: Any = None
        self._viewer: Any = None
        self._goal_mocap = mocap_index(self.model, "goal")
        self._goal_pos = self.data.mocap_pos[self._goal_mocap]  # a view: MjData's arrays never move

        self._observer = ob.Observer(self.model, self.task.parts)
        self.observation_layout: dict[str, slice] = dict(self._observer.layout)
        self._achieved = self.observation_layout[self.task.achieved]
        goal_size = self._achieved.stop - self._achieved.start
        box = functools.partial(gym.spaces.Box, -np.inf, np.inf, dtype=np.float64)
        self.observation_space = gym.spaces.Dict({  # type: ignore[assignment]
            "observation": box(shape=(self._observer.size,)),
            "achieved_goal": box(shape=(goal_size,)),
            "desired_goal": box(shape=(goal_size,)),
            **(self._images.spaces() if self._images is not None else {}),
        })
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self._state_buf = np.empty(mujoco.mj_stateSize(self.model, STATE_SPEC))
        self._started = False  # by reset() or set_state(): step() before either is gymnasium's ResetNeeded
        self.last_action: np.ndarray = np.zeros(4, np.float32)
        """The action of the last step, as clipped and applied (what a recorder stores)."""
        mujoco.mj_setState(self.model, self.data, self._start_state, STATE_SPEC)
        mujoco.mj_forward(self.model, self.data)
        self.robot.hold()

    # -- Gymnasium API -------------------------------------------------------------------

    @property
    def dt(self) -> float:
        """[s] the control period."""
        return CONTROL_DT

    @property
    def goal(self) -> np.ndarray:
        """The current goal (a copy); it lives in MjData as the goal marker's mocap position."""
        return self._goal_pos.copy()

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        return self._begin(lambda: self.task.reset(self.model, self.data, self.np_random, self._start))

    def reset_like(self, place: Callable[[mujoco.MjData], np.ndarray]
                   ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Begin an episode as `reset` does, with `place(data)` in place of the task's random draw: it
        puts things where they start (in MjData) and returns the goal [m, world]. An expert's private
        copy of a task (`fetch.experts.twin`) starts like the episode it observed this way."""
        return self._begin(lambda: place(self.data))

    def _begin(self, draw: Callable[[], np.ndarray]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        self._started = True
        mujoco.mj_setState(self.model, self.data, self._start_state, STATE_SPEC)
        goal = draw()
        self.data.mocap_pos[self._goal_mocap] = goal
        mujoco.mj_forward(self.model, self.data)
        self.robot.hold()
        obs, info = self._observe()
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], SupportsFloat, bool, bool,
                                                dict[str, Any]]:
        if not self._started:
            raise ResetNeeded("call env.reset() (or set_state) before env.step(); an episode needs a seed and a goal")
        a = np.asarray(action)
        if a.shape != (4,):
            raise ValueError(f"action must have shape (4,), got {a.shape}")
        a = checked_actions(a)  # the one check and clip between a device and the physics
        self.last_action = a
        move, grip = action_rule(a)
        self.robot.apply(move.tolist(), float(grip))
        self.robot.advance(self.model, self.data)
        obs, info = self._observe()
        reward = task_reward(self.reward_type, info["is_success"], info["distance"])
        if self.render_mode == "human":
            self.render()
        return obs, reward, False, False, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray,
                       info: Any = None) -> np.ndarray:
        """Sparse: 0 where the goal is reached else -1; dense: -distance [m]. Vectorised."""
        return task_reward(self.reward_type, self.task.is_success(achieved_goal, desired_goal),
                           goal_distance(achieved_goal, desired_goal))

    def _observe(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        # The sensors are current: mj_step1 (step) or mj_forward (reset, set_state) computed
        # them from the present state, so the observation is a function of the state alone.
        d = self.data
        vector = self._observer(d)
        achieved = vector[self._achieved]
        desired = self._goal_pos.copy()
        a, g = achieved.tolist(), desired.tolist()
        distance = math.dist(a, g)
        info: dict[str, Any] = {
            "is_success": 1.0 if self.task.success(a, g, distance) else 0.0,
            "distance": distance,
        }
        info.update(self.task.facts(d, vector))
        obs = {"observation": vector, "achieved_goal": achieved.copy(), "desired_goal": desired}
        if self._images is not None:  # of the state just observed: present() or mj_forward made it current
            obs.update(self._images.render(d))
        return obs, info

    # -- MuJoCo state --------------------------------------------------------------------

    def get_state(self, out: np.ndarray | None = None) -> np.ndarray:
        """The full integration state (`mj_getState`, mjSTATE_INTEGRATION): a fresh array, or
        written into `out` (float64, shape `(state_size,)`) and returned."""
        if out is not None:
            mujoco.mj_getState(self.model, self.data, out, STATE_SPEC)
            return out
        mujoco.mj_getState(self.model, self.data, self._state_buf, STATE_SPEC)
        return self._state_buf.copy()

    @property
    def state_size(self) -> int:
        """Length of `get_state()`."""
        return int(self._state_buf.shape[0])

    def set_state(self, state: np.ndarray) -> None:
        """Restore a state from `get_state`; the goal comes back with it."""
        state = np.asarray(state, dtype=np.float64)
        if state.shape != self._state_buf.shape:
            raise FetchError(f"state has shape {state.shape}; this env's states have shape "
                             f"{self._state_buf.shape}")
        mujoco.mj_setState(self.model, self.data, state, STATE_SPEC)
        self._started = True
        mujoco.mj_forward(self.model, self.data)
        # mj_forward overwrites the solver's warm start on some mujoco versions (3.3); put the
        # saved one back so the next step is bit-identical to the original run.
        mujoco.mj_setState(self.model, self.data, state, STATE_SPEC)

    def model_xml(self) -> str:
        """The compiled scene as MJCF (what a dataset stores to say which model it was made with)."""
        return str(self._compiled.spec.to_xml())

    def scene_spec(self) -> mujoco.MjSpec:
        """A copy of the `MjSpec` this env's model was compiled from (a viewer decorates its own copy)."""
        return self._compiled.spec.copy()

    def model_hash(self) -> str:
        """SHA-256 of the compiled model (MJB bytes) with its mesh and texture files named relative to
        their directories: equal models, equal hashes, wherever installed. (The model itself holds the
        files' absolute paths, so hashing it as it is gave two venvs on one machine two hashes.)"""
        return _portable_hash(type(self.task))

    def legacy_model_hash(self) -> str:
        """The hash datasets were stamped with before `model_hash` left the install paths out: the same
        model installed elsewhere has another. A dataset holding it still takes appends here."""
        return _mjb_hash(self._compiled.model)

    def observe(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """The observation and info of the current state (e.g. after `set_state`)."""
        return self._observe()

    def reflection(self) -> Reflection:
        """How a step of this task reflects in the vertical x-z plane through the start's grip site,
        for tasks symmetric about it (`Task.mirrors`): a reflected demo is a demo of the task."""
        if not self.task.mirrors:
            raise FetchError(f"{self.spec.id if self.spec else self.task.name} is not symmetric about the plane "
                             f"through its start (its scene or its start is not); tasks that are: "
                             f"{', '.join(mirroring_ids())}")
        plane = float(self._start.grip[1])
        parts = self.task.parts
        goal = next(p for p in parts if p.name == self.task.achieved)
        return Reflection(ob.mirror(parts, plane, FINGER_PAIRS), ob.mirror((goal,), plane, {}),
                          np.array([1.0, -1.0, 1.0, 1.0]))

    # -- rendering -----------------------------------------------------------------------

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to gym.make")
            return None
        if self.render_mode == "human":
            if self._viewer is None:
                self._viewer = rendering.HumanViewer(self.model, self.data, self.camera_name, self.hide_goal)
            self._viewer.sync(self.dt)
            return None
        if self._renderer is None:
            self._renderer = rendering.OffscreenRenderer(self.model, self.width, self.height)
        return self._renderer.render(self.data, self.camera_name,
                                     depth=self.render_mode == "depth_array", hide_goal=self.hide_goal)

    def images(self, states: np.ndarray, threads: int = 1) -> dict[str, np.ndarray]:
        """Per camera, the images of N `get_state` states, as observations hold them; the env ends in the last."""
        cams = self._images
        return cams.render_states(states, self.set_state, self.data, STATE_SPEC, threads) if cams else {}

    def close(self) -> None:
        if self._images is not None:
            self._images.close()
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    # -- pickling: the same env, in the same state ----------------------------------------

    def __getstate__(self) -> dict[str, Any]:
        return {"kwargs": self._kwargs, "state": self.get_state(),
                "rng": self.np_random.bit_generator.state, "rng_seed": self._np_random_seed}

    def __setstate__(self, saved: dict[str, Any]) -> None:
        self.__init__(**saved["kwargs"])  # type: ignore[misc]
        self.set_state(saved["state"])
        self.np_random.bit_generator.state = saved["rng"]
        self._np_random_seed = saved["rng_seed"]
