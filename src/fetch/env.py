"""The Gymnasium env: one Fetch robot composed with one task."""

from __future__ import annotations

import copy
import functools
import math
import reprlib
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple, SupportsFloat

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.error import ResetNeeded

from fetch import camera_obs, rendering
from fetch import observation as ob
from fetch.compiled import STATE_SPEC, compiled_task, mjb_hash, portable_hash
from fetch.errors import FetchError, UnknownNameError
from fetch.looks import LOOKS, Looks, check_looks
from fetch.robot import Robot, checked_action
from fetch.tasks import mirroring_ids, task_class
from fetch.tasks.base import FINGER_PAIRS, REWARD_TYPES, Task, goal_distance, mocap_index
from fetch.tasks.base import reward as task_reward
from fetch.timing import CONTROL_DT

RENDER_MODES = ("human", "rgb_array", "depth_array")
RECORDED_KWARGS: dict[str, tuple[str | bool, ...]] = {"reward_type": REWARD_TYPES, "hide_goal": (False, True),
                                                      "looks": LOOKS}
"""The `FetchEnv` arguments a file may set (a dataset's `env_kwargs`, and a run's, copied from its dataset), with
their values: how rewards are given and how the scene looks. The others are the caller's: the task is the
registered id's, the window and the observation's images the tool's or the policy's; read from a file they would
clash with the caller's own or size a renderer."""


def recorded_kwargs(raw: object) -> dict[str, str | bool]:
    """`raw`, env kwargs read from a file, when it is a mapping of `RECORDED_KWARGS` to one of their values; else a
    one-line FetchError saying what is wrong."""
    if not isinstance(raw, dict):
        raise FetchError(f"env_kwargs must be an object of {', '.join(RECORDED_KWARGS)}, got {type(raw).__name__}")
    for key, value in raw.items():
        if key not in RECORDED_KWARGS:
            raise FetchError(f"env_kwargs {reprlib.repr(key)} cannot come from a file; those that can: "
                             f"{', '.join(RECORDED_KWARGS)}")
        # exact types: JSON's 1 is no more hide_goal=True than "sparse " is a reward type
        if not any(type(value) is type(c) and value == c for c in RECORDED_KWARGS[key]):
            raise FetchError(f"env_kwargs {key}={reprlib.repr(value)}: choose one of "
                             f"{', '.join(repr(c) for c in RECORDED_KWARGS[key])}")
    return dict(raw)


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
    `image_quality` (`rendering.IMAGE_QUALITIES`: "fast", the default, or "full"). `looks="random"` draws
    each episode's colours, lights and camera mounts from its reset seed (`fetch.looks`; the physics
    is untouched); "plain", the default, draws the scene as modelled.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": round(1.0 / CONTROL_DT)}

    def __init__(self, task: str = "pick_place", reward_type: str = "sparse",
                 render_mode: str | None = None, width: int = 480, height: int = 480,
                 camera_name: str = "front", hide_goal: bool = False, cameras: Sequence[str] = (),
                 image_size: int = camera_obs.DEFAULT_IMAGE_SIZE,
                 image_quality: str = rendering.DEFAULT_IMAGE_QUALITY, looks: str = "plain") -> None:
        if reward_type not in REWARD_TYPES:
            raise UnknownNameError("reward_type", reward_type, REWARD_TYPES)
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise UnknownNameError("render_mode", render_mode, RENDER_MODES)
        if int(width) <= 0 or int(height) <= 0:
            raise FetchError(f"width and height must be positive pixels, got {width}x{height}")
        self._kwargs = dict(task=task, reward_type=reward_type, render_mode=render_mode,
                            width=int(width), height=int(height), camera_name=camera_name,
                            hide_goal=hide_goal, cameras=cameras, image_size=image_size,
                            image_quality=image_quality, looks=check_looks(looks))
        compiled = compiled_task(task_class(task))
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
        self.looks_mode: str = looks
        """`looks`, as given: "plain" or "random" (`fetch.looks.LOOKS`)."""
        self.looks: Looks | None = None
        """This episode's looks (`fetch.looks`): drawn at each reset under looks="random", else None."""
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
        if self.looks_mode == "random":  # from a child of the reset seed's sequence: the task's draws stay
            self.looks = Looks.draw(self.model, self.np_random.spawn(1)[0])
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
        # the one check and clip between a device and the physics
        self.last_action, move, grip = checked_action(a)
        self.robot.apply(move, grip)
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
        # The sensors are current: `present` (step) or mj_forward (reset, set_state) computed
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
            obs.update(self._images.render(d, self.looks))
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
        return portable_hash(type(self.task))

    def legacy_model_hash(self) -> str:
        """The hash datasets were stamped with before `model_hash` left the install paths out: the same
        model installed elsewhere has another. A dataset holding it still takes appends here."""
        return mjb_hash(self._compiled.model)

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
        return self._renderer.render(self.data, self.camera_name, depth=self.render_mode == "depth_array",
                                     hide_goal=self.hide_goal, looks=self.looks)

    def images(self, states: np.ndarray, threads: int = 1,
               looks: Sequence[Looks | None] | None = None) -> dict[str, np.ndarray]:
        """Per camera, the images of N `get_state` states, as observations hold them, each drawn with its
        `looks` (default: this episode's); the env ends in the last."""
        cams, each = self._images, [self.looks] * len(states) if looks is None else looks
        return cams.render_states(states, self.set_state, self.data, STATE_SPEC, threads, each) if cams else {}

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
        return {"kwargs": self._kwargs, "state": self.get_state(), "looks": self.looks,
                "rng": self.np_random.bit_generator.state, "rng_seed": self._np_random_seed}

    def __setstate__(self, saved: dict[str, Any]) -> None:
        self.__init__(**saved["kwargs"])  # type: ignore[misc]
        self.set_state(saved["state"])
        self.looks = saved.get("looks")
        self.np_random.bit_generator.state = saved["rng"]
        self._np_random_seed = saved["rng_seed"]
