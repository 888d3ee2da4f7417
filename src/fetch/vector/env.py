"""FetchVectorEnv: N worlds of one task in one process, stepped together on C threads (Gymnasium 1.x).

Each world steps exactly as `gym.make(id)` does (same seeds and actions: the same observations,
rewards, infos and `get_state()`, bit for bit): the action rule is `Robot.apply_batch`, the physics
runs in `worlds.py`, observations come from `Observer.batch`. Resets go through a single `FetchEnv`
(the template), one world at a time: a reset draws from that world's own `np.random.Generator`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.core import RenderFrame
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fetch import observation as ob
from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.env import FetchEnv
from fetch.errors import FetchError, UnknownNameError
from fetch.looks import Looks
from fetch.rendering import DEFAULT_IMAGE_QUALITY
from fetch.robot import action_rule, checked_actions
from fetch.tasks.base import mocap_index
from fetch.vector.observe import BatchObserver
from fetch.vector.worlds import StateLayout, Worlds, make_worlds

Obs = dict[str, np.ndarray]
RENDER_MODES = ("rgb_array", "depth_array")


class FetchVectorEnv(VectorEnv[Obs, np.ndarray, np.ndarray]):
    """`num_envs` worlds of one Fetch task, stepped in parallel on `nthread` C threads (0: every
    CPU; mujoco >= 4.0, else one after another). Gymnasium's VectorEnv API: batched Dict
    observations, rewards, terminated/truncated and infos with `_key` masks, as `SyncVectorEnv`.

    `max_episode_steps` truncates as `gym.make`'s TimeLimit; `autoreset_mode` is one of Gymnasium's `AutoresetMode`s;
    `render()` renders the worlds in `render_worlds` (default: all); the other keyword arguments are `FetchEnv`'s
    (`render_mode` "human" excepted; with `cameras`, each world's images are the template's renders of its state).
    """

    metadata: dict[str, Any] = {"render_modes": list(RENDER_MODES), "render_fps": FetchEnv.metadata["render_fps"],
                                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int, task: str = "pick_place", max_episode_steps: int | None = None,
                 reward_type: str = "sparse", render_mode: str | None = None, width: int = 480,
                 height: int = 480, camera_name: str = "front", hide_goal: bool = False,
                 autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP, nthread: int = 0,
                 render_worlds: Sequence[int] | None = None, cameras: Sequence[str] = (),
                 image_size: int = DEFAULT_IMAGE_SIZE, image_quality: str = DEFAULT_IMAGE_QUALITY,
                 looks: str = "plain") -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise FetchError(f"num_envs must be a whole number >= 1, got {num_envs!r}")
        self.num_envs = int(num_envs)
        if max_episode_steps is not None and (isinstance(max_episode_steps, bool) or int(max_episode_steps) < 1):
            raise FetchError(f"max_episode_steps must be >= 1 or None, got {max_episode_steps!r}")
        if isinstance(nthread, bool) or not isinstance(nthread, (int, np.integer)) or nthread < 0:
            raise FetchError(f"nthread must be a whole number >= 0 (0: every CPU), got {nthread!r}")
        modes = tuple(m.value for m in AutoresetMode)
        if not isinstance(autoreset_mode, AutoresetMode) and autoreset_mode not in modes:
            raise UnknownNameError("autoreset_mode", str(autoreset_mode), modes)
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise UnknownNameError("render_mode", render_mode, RENDER_MODES)
        self.render_worlds = self._check_worlds(render_worlds)

        # The template: validates the env's own arguments, resets one world at a time and renders.
        self._env = FetchEnv(task=task, reward_type=reward_type, render_mode=render_mode, width=width, height=height,
                             camera_name=camera_name, hide_goal=hide_goal, cameras=cameras, image_size=image_size,
                             image_quality=image_quality, looks=looks)
        env = self._env
        self.task, self.robot, self.model = env.task, env.robot, env.model
        self.reward_type = reward_type
        self.render_mode = render_mode
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        self.single_observation_space = env.observation_space
        self.observation_space = batch_space(env.observation_space, self.num_envs)
        self.single_action_space, self.action_space = env.action_space, batch_space(env.action_space, self.num_envs)
        self.observation_layout = dict(env.observation_layout)

        self._worlds: Worlds = make_worlds(self.model, self.num_envs, self.robot.hand, int(nthread))
        if not self._worlds.parallel and self.num_envs > 1:
            gym.logger.warn(f"FetchVectorEnv steps its {self.num_envs} worlds one after another, on one core (same "
                            f"results): mujoco.batch, the threaded path of mujoco 4.0 and later, is not available "
                            f"(mujoco {mujoco.__version__})")
        self._layout = StateLayout(self.model)
        self._worlds.state[:] = env.get_state()  # every world as a new env is before its first reset
        self._observer = BatchObserver(self.task, ob.Observer(self.model, self.task.parts), reward_type)
        self._goal_mocap = mocap_index(self.model, "goal")
        self._rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self._seeds: list[int | None] = [None] * self.num_envs
        self._looks: list[Looks | None] = [None] * self.num_envs  # each world's episode's (looks="random")
        self._elapsed = np.zeros(self.num_envs, dtype=np.int64)
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        # What the last reset or step returned: a masked reset returns the other worlds' as they were.
        self._last_obs = self._empty_obs(self.num_envs)

    # -- Gymnasium VectorEnv API --------------------------------------------------------------

    @property
    def nthread(self) -> int:
        """C threads the worlds step on (1 where mujoco has no `mujoco.batch`)."""
        return self._worlds.nthread

    @property
    def parallel(self) -> bool:
        """Whether the worlds step on C threads (mujoco >= 4.0) or one after another."""
        return self._worlds.parallel

    @property  # type: ignore[misc]
    def np_random(self) -> tuple[np.random.Generator, ...]:  # type: ignore[override]
        """Each world's generator, as `SyncVectorEnv.np_random` (one is made for a world that has none)."""
        return tuple(self._rng(i) for i in range(self.num_envs))

    @property
    def np_random_seed(self) -> tuple[int | None, ...]:  # type: ignore[override]
        """Each world's seed, as `SyncVectorEnv.np_random_seed` (a world with no generator gets one)."""
        for i in range(self.num_envs):
            self._rng(i)
        return tuple(self._seeds)

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Obs, dict[str, Any]]:
        """Reset every world, or those in `options["reset_mask"]`; an int seed gives world i seed + i,
        as `SyncVectorEnv` does."""
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (list, tuple)):
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"seed must be None, an int or a list of num_envs={n} seeds; got {len(seeds)} seeds")
        else:
            seeds = [int(seed) + i for i in range(n)]
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            mask = np.ones(n, dtype=np.bool_)
        elif not isinstance(mask, np.ndarray) or mask.shape != (n,) or mask.dtype != np.bool_:
            raise ValueError(f"options['reset_mask'] must be a bool numpy array of shape ({n},), got {mask!r}")
        elif not mask.any():
            raise ValueError("options['reset_mask'] resets no world; set at least one True")
        ids = np.flatnonzero(mask)
        self._autoreset[ids] = False
        obs = {key: value.copy() for key, value in self._last_obs.items()}
        infos: dict[str, Any] = {}
        for i in ids.tolist():
            world_obs, info = self._reset_world(i, seeds[i])
            for key, value in world_obs.items():
                obs[key][i] = value
            infos = self._add_info(infos, info, i)
        self._last_obs = {key: value.copy() for key, value in obs.items()}  # not the caller's arrays
        return obs, infos

    def step(self, actions: np.ndarray) -> tuple[Obs, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every world with its row of `actions` (num_envs, 4): batched results, autoreset as
        `autoreset_mode` says."""
        n = self.num_envs
        if n == 1:
            return self._step_one(self._check_shape(actions)[0])
        a = self._check_actions(actions)
        mode = self.autoreset_mode
        ended = self._autoreset.any()
        if ended and mode == AutoresetMode.DISABLED:
            raise FetchError(f"worlds {np.flatnonzero(self._autoreset).tolist()} ended their episodes; with "
                             "autoreset_mode=disabled reset them (reset(options={'reset_mask': ...})) first")
        resetting = np.flatnonzero(self._autoreset) if ended and mode == AutoresetMode.NEXT_STEP else None
        if resetting is None:  # every world steps: the batched results are the results
            obs, rewards, step_infos = self._step_worlds(None, a)
            self._elapsed += 1
            infos = {}
            for key, value in step_infos.items():
                infos[key], infos[f"_{key}"] = value, np.ones(n, dtype=np.bool_)
        else:
            stepping = np.flatnonzero(~self._autoreset)
            obs, rewards = self._empty_obs(n), np.zeros(n, dtype=np.float64)
            infos = {}
            if stepping.size:
                step_obs, step_rewards, step_infos = self._step_worlds(stepping, a[stepping])
                for key, value in step_obs.items():
                    obs[key][stepping] = value
                rewards[stepping] = step_rewards
                self._elapsed[stepping] += 1
                infos = self._add_infos(infos, step_infos, stepping)
            for i in resetting.tolist():
                world_obs, info = self._reset_world(i, None)
                for key, value in world_obs.items():
                    obs[key][i] = value
                infos = self._add_info(infos, info, i)
        terminated = np.zeros(n, dtype=np.bool_)  # no task ends an episode early: success is in info
        if self.max_episode_steps is None:
            truncated = np.zeros(n, dtype=np.bool_)
        else:
            truncated = self._elapsed >= self.max_episode_steps
            if resetting is not None:
                truncated[resetting] = False
        if mode == AutoresetMode.SAME_STEP and truncated.any():
            for i in np.flatnonzero(truncated).tolist():
                final_info = {key: infos[key][i] for key in step_infos}
                final_obs = {key: obs[key][i].copy() for key in obs}
                infos = self._add_info(infos, {"final_obs": final_obs, "final_info": final_info}, i)
                world_obs, info = self._reset_world(i, None)
                for key, value in world_obs.items():
                    obs[key][i] = value
                infos = self._add_info(infos, info, i)
        self._autoreset = terminated | truncated
        self._last_obs = {key: value.copy() for key, value in obs.items()}  # not the caller's arrays
        return obs, rewards, terminated, truncated, infos

    def render(self) -> tuple[RenderFrame, ...] | None:
        """Frames of the worlds in `render_worlds` (all by default), in that order."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make_vec")
            return None
        return tuple(cast(RenderFrame, self.render_world(i)) for i in self.render_worlds)

    def render_world(self, world: int) -> np.ndarray | None:
        """One world's frame (`render_mode` rgb_array or depth_array)."""
        (world,) = self._check_worlds([world])
        self._env.set_state(self._worlds.state[world])
        self._env.looks = self._looks[world]
        return self._env.render()

    def close_extras(self, **kwargs: Any) -> None:
        self._env.close()
        self._worlds.close()

    # -- per world -------------------------------------------------------------------------

    def get_state(self, world: int) -> np.ndarray:
        """World `world`'s full integration state, as `FetchEnv.get_state` (a copy)."""
        (world,) = self._check_worlds([world])
        return self._worlds.state[world].copy()

    def set_state(self, world: int, state: np.ndarray) -> None:
        """Restore world `world` to a state from `get_state` (of this or a single env of the same id), as
        `FetchEnv.set_state`: its next step is the one that state's env would take; its step count is kept."""
        (world,) = self._check_worlds([world])
        state = np.asarray(state, dtype=np.float64)
        if state.shape != self._worlds.state.shape[1:]:
            raise FetchError(f"state has shape {state.shape}; this env's states have shape "
                             f"{self._worlds.state.shape[1:]}")
        self._worlds.state[world] = state
        if self.num_envs == 1:  # the template holds the one world's MjData
            self._env.set_state(state)

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None) -> np.ndarray:
        """`FetchEnv.compute_reward`: vectorised over any leading axes (HER)."""
        return self._env.compute_reward(achieved_goal, desired_goal, info)

    # -- inside ----------------------------------------------------------------------------

    def _rng(self, world: int) -> np.random.Generator:
        rng = self._rngs[world]
        if rng is None:
            rng, seed = seeding.np_random()
            self._rngs[world], self._seeds[world] = rng, seed
        return rng

    def _reset_world(self, world: int, seed: int | None) -> tuple[Obs, dict[str, Any]]:
        """Reset one world through the template, with that world's generator (or a new one from `seed`)."""
        env = self._env
        if seed is None:
            env.np_random = self._rng(world)
            obs, info = env.reset()
        else:
            obs, info = env.reset(seed=seed)
            self._rngs[world], self._seeds[world] = env.np_random, env.np_random_seed
        env.get_state(self._worlds.state[world])
        self._elapsed[world], self._looks[world] = 0, env.looks
        return obs, info

    def _check_shape(self, actions: Any) -> np.ndarray:
        a = np.asarray(actions)
        if a.shape != (self.num_envs, 4):
            raise ValueError(f"actions must have shape ({self.num_envs}, 4), one row of 4 per world; got {a.shape}")
        return a

    def _check_actions(self, actions: Any) -> np.ndarray:
        return checked_actions(self._check_shape(actions))  # FetchEnv.step's check and clip

    def _step_worlds(self, ids: np.ndarray | None, a: np.ndarray) -> tuple[Obs, np.ndarray, dict[str, np.ndarray]]:
        """One control step of the worlds `ids` (sorted; None: every world), as `FetchEnv.step` does
        for one."""
        worlds, robot, layout = self._worlds, self.robot, self._layout
        sel: slice | np.ndarray = slice(None) if ids is None else ids
        # Every world: views of the live rows; some: a copy of theirs, written back.
        rows = worlds.state if ids is None else worlds.state[ids]
        qpos, ctrl = layout.view(rows, "qpos"), layout.view(rows, "ctrl")
        mocap_pos, mocap_quat = layout.view(rows, "mocap_pos"), layout.view(rows, "mocap_quat")
        robot.apply_batch(mocap_pos, mocap_quat, ctrl, qpos, *action_rule(a))
        if ids is not None:
            worlds.state[ids] = rows
        worlds.step(ids)
        if robot.config.block_gripper:
            # The fingers held shut are reset after the physics, before the state is observed.
            rows = worlds.state if ids is None else worlds.state[ids]
            layout.view(rows, "qpos")[:, robot.finger_qpos] = 0.0
            if ids is not None:
                worlds.state[ids] = rows
        else:
            # The next action moves from the hand's pose where gymnasium-robotics v4 reads it: at
            # the start of the last substep (see Robot.advance).
            reference = worlds.hand_pos[sel].copy(), worlds.hand_quat[sel].copy()
        worlds.sense(ids)
        if robot.config.block_gripper:
            reference = worlds.hand_pos[sel], worlds.hand_quat[sel]  # after the reset: the present pose
        rows = worlds.state if ids is None else worlds.state[ids]
        layout.view(rows, "mocap_pos")[:, robot.mocap] = reference[0]
        layout.view(rows, "mocap_quat")[:, robot.mocap] = reference[1]
        if ids is not None:
            worlds.state[ids] = rows
        goals = layout.view(rows, "mocap_pos")[:, self._goal_mocap].copy()
        obs, rewards, info = self._observer(worlds.sensordata[sel], goals, layout.view(rows, "qpos"))
        looks = self._looks if ids is None else [self._looks[i] for i in ids]  # the template's images, nthread threads
        return {**obs, **self._env.images(rows, self.nthread, looks)}, rewards, info

    def _step_one(self, action: np.ndarray) -> tuple[Obs, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """`step` of one world: nothing to spread over threads, and numpy's cost per call exceeds
        FetchEnv's scalar step's, so the world steps as the template itself (which holds its state;
        FetchEnv.step checks the action's dtype and finiteness and clips it), the episode kept in
        scalars, the autoreset modes as in `step`."""
        env, mode = self._env, self.autoreset_mode
        ended = bool(self._autoreset[0])
        if ended and mode == AutoresetMode.DISABLED:
            raise FetchError("worlds [0] ended their episodes; with autoreset_mode=disabled reset them "
                             "(reset(options={'reset_mask': ...})) first")
        extra: dict[str, Any] = {}
        if ended and mode == AutoresetMode.NEXT_STEP:
            obs, info = self._reset_world(0, None)
            reward: SupportsFloat = 0.0
            truncated = False
        else:
            obs, reward, _, _, info = env.step(action)
            env.get_state(self._worlds.state[0])
            elapsed = int(self._elapsed[0]) + 1
            self._elapsed[0] = elapsed
            truncated = self.max_episode_steps is not None and elapsed >= self.max_episode_steps
            if truncated and mode == AutoresetMode.SAME_STEP:
                extra = self._add_info({}, {"final_obs": obs, "final_info": info}, 0)
                obs, info = self._reset_world(0, None)
        self._autoreset[0] = truncated
        batched = {key: value[None] for key, value in obs.items()}
        self._last_obs = {key: value.copy() for key, value in batched.items()}
        infos = extra
        for key, value in info.items():
            infos[key], infos[f"_{key}"] = np.array([value], dtype=np.float64), np.array([True])
        return (batched, np.array([reward], dtype=np.float64), np.array([False]), np.array([truncated]), infos)

    def _add_infos(self, infos: dict[str, Any], values: dict[str, np.ndarray], ids: np.ndarray) -> dict[str, Any]:
        """`_add_info` for many worlds at once: each key an (num_envs,) float array with its `_key` mask."""
        for key, value in values.items():
            if key not in infos:
                infos[key] = np.zeros(self.num_envs, dtype=value.dtype)
                infos[f"_{key}"] = np.zeros(self.num_envs, dtype=np.bool_)
            infos[key][ids] = value
            infos[f"_{key}"][ids] = True
        return infos

    def _empty_obs(self, n: int) -> Obs:
        return {key: np.zeros((n, *space.shape), dtype=space.dtype)  # type: ignore[misc]
                for key, space in self.single_observation_space.spaces.items()}  # type: ignore[attr-defined]

    def _check_worlds(self, worlds: Sequence[int] | None) -> list[int]:
        if worlds is None:
            return list(range(self.num_envs))
        worlds = list(worlds)
        for w in worlds:
            if isinstance(w, bool) or not isinstance(w, (int, np.integer)) or not 0 <= w < self.num_envs:
                raise FetchError(f"world {w!r} is not one of 0..{self.num_envs - 1}")
        return [int(w) for w in worlds]
