"""FetchVectorEnv: N worlds in one process equal N `gym.make` envs bit for bit, autoreset and seed as
`SyncVectorEnv`, and refuse bad input with one line."""

from __future__ import annotations

import contextlib
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import fetch
from fetch.errors import FetchError, UnknownNameError
from fetch.vector import FetchVectorEnv, has_batch
from fetch.vector import worlds as worlds_module


def assert_same(ours: Any, theirs: Any, where: str = "") -> None:
    """Equal bit for bit: same keys, dtypes, shapes and values (objects and dicts recursively)."""
    if isinstance(theirs, tuple):
        assert isinstance(ours, tuple) and len(ours) == len(theirs), where
        for k, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            assert_same(a, b, f"{where}[{k}]")
    elif isinstance(theirs, dict):
        assert isinstance(ours, dict) and ours.keys() == theirs.keys(), f"{where}: {ours.keys()} != {theirs.keys()}"
        for key in theirs:
            assert_same(ours[key], theirs[key], f"{where}.{key}")
    elif isinstance(theirs, np.ndarray) and theirs.dtype == object:
        assert isinstance(ours, np.ndarray) and ours.shape == theirs.shape, where
        for k, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            assert_same(a, b, f"{where}[{k}]")
    elif theirs is None:
        assert ours is None, where
    else:
        a, b = np.asarray(ours), np.asarray(theirs)
        assert a.dtype == b.dtype and a.shape == b.shape, f"{where}: {a.dtype}{a.shape} != {b.dtype}{b.shape}"
        assert np.array_equal(a, b), f"{where}: {a} != {b}"


def both(env_id: str, n: int, **kwargs: Any) -> tuple[gym.vector.VectorEnv, gym.vector.SyncVectorEnv]:
    """Ours and Gymnasium's SyncVectorEnv of `gym.make` envs, same id and arguments."""
    mode = kwargs.pop("autoreset_mode", AutoresetMode.NEXT_STEP)
    ours = fetch.make_vec(env_id, n, autoreset_mode=mode, nthread=2, **kwargs)
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode},
                        **kwargs)
    return ours, sync


def step_both(ours: gym.vector.VectorEnv, sync: gym.vector.SyncVectorEnv, actions: np.ndarray, where: str) -> tuple:
    got, want = ours.step(actions), sync.step(actions)
    for name, a, b in zip(("obs", "reward", "terminated", "truncated", "info"), got, want, strict=True):
        assert_same(a, b, f"{where} {name}")
    for i, env in enumerate(sync.envs):
        assert_same(ours.unwrapped.get_state(i), env.unwrapped.get_state(), f"{where} state of world {i}")
    return got


def test_every_task_is_bit_identical_to_single_envs(env_id: str) -> None:
    # 55 steps: past the 50-step horizon, so truncation and the next-step autoreset are covered;
    # actions beyond [-1, 1] (clipped), float32 and float64 (scaled in their own precision).
    ours, sync = both(env_id, 3)
    assert_same(ours.reset(seed=11), sync.reset(seed=11), "reset")
    rng = np.random.default_rng(0)
    truncated_seen = False
    for t in range(55):
        actions = rng.uniform(-1.3, 1.3, (3, 4))
        _, _, _, truncated, _ = step_both(ours, sync, actions.astype(np.float32 if t % 2 else np.float64), f"step {t}")
        truncated_seen |= bool(truncated.all())
    assert truncated_seen
    ours.close()
    sync.close()


@pytest.mark.parametrize("path", ["serial", "threaded-sensing", "one-world"])
@pytest.mark.parametrize("env_id", ["PickPlace-v2", "Reach-v2", "Drawer-open-v2"])
def test_other_paths_are_bit_identical(env_id: str, path: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # The serial path is what mujoco < 4.0 runs; threaded sensing what machines with >= 4 threads
    # run; one world steps through FetchEnv itself.
    n = 1 if path == "one-world" else 3
    if path == "serial":
        monkeypatch.setattr(worlds_module, "has_batch", lambda: False)
    elif path == "threaded-sensing":
        if not has_batch():
            pytest.skip("needs mujoco.batch (mujoco >= 4.0)")
        monkeypatch.setattr(worlds_module, "THREADED_SENSING_FROM", 1)
    with contextlib.ExitStack() as expect:
        if n > 1 and (path == "serial" or not has_batch()):
            expect.enter_context(pytest.warns(UserWarning, match="one after another, on one core"))
        ours, sync = both(env_id, n, max_episode_steps=6, reward_type="dense")
    assert ours.unwrapped.parallel == (path != "serial" and has_batch())
    assert_same(ours.reset(seed=3), sync.reset(seed=3), "reset")
    rng = np.random.default_rng(1)
    for t in range(14):
        step_both(ours, sync, rng.uniform(-1, 1, (n, 4)).astype(np.float32), f"step {t}")


@pytest.mark.parametrize("n", [1, 3])
@pytest.mark.parametrize("mode", list(AutoresetMode))
def test_autoreset_modes_match_sync(mode: AutoresetMode, n: int) -> None:
    ours, sync = both("PickPlace-v2", n, max_episode_steps=4, autoreset_mode=mode)
    assert ours.metadata["autoreset_mode"] == mode
    assert_same(ours.reset(seed=5), sync.reset(seed=5), "reset")
    rng = np.random.default_rng(2)
    actions = rng.uniform(-1, 1, (40, n, 4)).astype(np.float32)
    for t in range(2):
        step_both(ours, sync, actions[t], f"step {t}")
    # Worlds 0 and 2 start again, so the worlds' episodes end at different steps from here on.
    mask = np.array([True, False, True][:n])
    assert_same(ours.reset(options={"reset_mask": mask.copy()}), sync.reset(options={"reset_mask": mask.copy()}),
                "masked reset")
    for t in range(2, 14):
        if mode == AutoresetMode.DISABLED:
            ended = ours.unwrapped._autoreset.copy()
            if ended.any():
                with pytest.raises(FetchError, match="ended their episodes"):
                    ours.step(actions[t])
                assert_same(ours.reset(options={"reset_mask": ended.copy()}),
                            sync.reset(options={"reset_mask": ended.copy()}), f"reset at {t}")
        _, _, _, truncated, info = step_both(ours, sync, actions[t], f"step {t}")
        if mode == AutoresetMode.SAME_STEP and truncated.any():
            assert set(np.flatnonzero(info["_final_obs"])) == set(np.flatnonzero(truncated))


def test_seeds_as_sync_vector_env() -> None:
    ours, sync = both("Push-v2", 3)
    obs, _ = ours.reset(seed=7)
    for i in range(3):
        single, _ = gym.make("Push-v2").reset(seed=7 + i)
        assert_same(obs["observation"][i], single["observation"], f"world {i}")
    assert ours.unwrapped.np_random_seed == (7, 8, 9)
    sync.reset(seed=7)
    # Unseeded resets continue each world's own generator, as SyncVectorEnv's envs do.
    assert_same(ours.reset(), sync.reset(), "reset after seeding")
    assert_same(ours.reset(seed=[4, None, 6]), sync.reset(seed=[4, None, 6]), "list of seeds")
    assert ours.unwrapped.np_random_seed == (4, 8, 6)
    with pytest.raises(ValueError, match="num_envs=3"):
        ours.reset(seed=[1, 2])


def test_unseeded_worlds_differ() -> None:
    env = fetch.make_vec("PickPlace-v2", 4)
    obs, _ = env.reset()
    assert len({tuple(g) for g in obs["desired_goal"].tolist()}) == 4


def test_make_vec_entry_point() -> None:
    env = gym.make_vec("PickPlace-v2", num_envs=2, vectorization_mode="vector_entry_point")
    assert isinstance(env, FetchVectorEnv) and env.num_envs == 2
    assert env.max_episode_steps == 50 and env.spec is not None and env.spec.id == "PickPlace-v2"
    assert isinstance(env.metadata["autoreset_mode"], AutoresetMode)
    assert env.action_space.shape == (2, 4) and env.observation_space["observation"].shape == (2, 25)
    env.close()
    assert isinstance(fetch.make_vec("Drawer-open-v2", 1), FetchVectorEnv)
    if has_batch():
        threaded = fetch.make_vec("Reach-v2", 3, nthread=2).unwrapped
        assert threaded.parallel and threaded.nthread == 2


def test_observations_are_fresh_arrays() -> None:
    env = fetch.make_vec("Reach-v2", 2)
    obs, _ = env.reset(seed=0)
    kept = {k: v.copy() for k, v in obs.items()}
    env.step(np.ones((2, 4), np.float32))
    assert_same(obs, kept, "first observation after the next step")


@pytest.mark.parametrize("actions, match", [
    (np.zeros(4, np.float32), r"shape \(3, 4\).*got \(4,\)"),
    (np.zeros((3, 3), np.float32), r"shape \(3, 4\).*got \(3, 3\)"),
    (np.zeros((3, 4), np.complex128), "real numbers"),
    (np.array([["a"] * 4] * 3), "real numbers"),
    (np.array([[0, 0, 0, 0], [0, np.nan, 0, 0], [0, 0, 0, 0]]), r"worlds \[1\] are not finite"),
    (np.array([[0, 0, np.inf, 0]] * 3, np.float32), r"worlds \[0, 1, 2\] are not finite"),
])
def test_bad_actions_are_refused_before_any_world_steps(actions: np.ndarray, match: str) -> None:
    env = fetch.make_vec("PickPlace-v2", 3)
    env.reset(seed=0)
    before = [env.unwrapped.get_state(i) for i in range(3)]
    with pytest.raises(ValueError, match=match):
        env.step(actions)
    for i in range(3):
        assert_same(env.unwrapped.get_state(i), before[i], f"world {i}")


@pytest.mark.parametrize("kwargs, error, match", [
    ({"num_envs": 0}, FetchError, "num_envs must be"),
    ({"num_envs": 2, "autoreset_mode": "sometimes"}, UnknownNameError, "NextStep, SameStep, Disabled"),
    ({"num_envs": 2, "render_mode": "human"}, UnknownNameError, "rgb_array"),
    ({"num_envs": 2, "render_worlds": [2]}, FetchError, "0..1"),
    ({"num_envs": 2, "nthread": -1}, FetchError, "nthread"),
    ({"num_envs": 2, "reward_type": "shaped"}, UnknownNameError, "sparse"),
    ({"num_envs": 2, "task": "Stack-v2"}, UnknownNameError, "PickPlace-v2"),
    ({"num_envs": 2, "max_episode_steps": 0}, FetchError, "max_episode_steps"),
])
def test_bad_arguments(kwargs: dict[str, Any], error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        FetchVectorEnv(**kwargs)


def test_bad_reset_mask() -> None:
    env = fetch.make_vec("Reach-v2", 2)
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        env.reset(options={"reset_mask": np.array([True])})
    with pytest.raises(ValueError, match="no world"):
        env.reset(options={"reset_mask": np.zeros(2, bool)})


def test_render_chosen_worlds() -> None:
    env = fetch.make_vec("Bin-pick-v2", 3, render_mode="rgb_array", width=64, height=48, render_worlds=[2, 0])
    env.reset(seed=1)
    actions = np.tile(np.array([0.5, -0.3, 0.2, 1.0], np.float32), (3, 1))
    env.step(actions)
    frames = env.render()
    assert isinstance(frames, tuple) and len(frames) == 2
    single = gym.make("Bin-pick-v2", render_mode="rgb_array", width=64, height=48)
    for frame, world in zip(frames, (2, 0), strict=True):
        single.reset(seed=1 + world)
        single.step(actions[world])
        assert_same(frame, single.render(), f"frame of world {world}")
    assert not np.array_equal(frames[0], frames[1])  # two different worlds
    with pytest.raises(FetchError, match="0..2"):
        env.unwrapped.render_world(3)


def test_one_world_refuses_bad_actions() -> None:
    env = fetch.make_vec("Slide-v2", 1)
    env.reset(seed=0)
    before = env.unwrapped.get_state(0)
    with pytest.raises(ValueError, match=r"shape \(1, 4\).*got \(4,\)"):
        env.step(np.zeros(4, np.float32))
    with pytest.raises(ValueError, match="not finite"):
        env.step(np.array([[0.0, np.nan, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="real numbers"):
        env.step(np.zeros((1, 4), np.complex64))
    assert_same(env.unwrapped.get_state(0), before, "world 0")


@pytest.mark.parametrize("n", [1, 3])
def test_set_state_continues_as_the_single_env(n: int) -> None:
    # A world restored to a single env's mid-episode state steps on exactly as that env does.
    single = gym.make("PickPlace-v2")
    single.reset(seed=9)
    rng = np.random.default_rng(4)
    for _ in range(7):
        single.step(rng.uniform(-1, 1, 4).astype(np.float32))
    env = fetch.make_vec("PickPlace-v2", n)
    env.reset(seed=0)
    world = n - 1
    env.unwrapped.set_state(world, single.unwrapped.get_state())
    for t in range(5):
        actions = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        obs, reward, _, _, info = env.step(actions)
        want_obs, want_reward, _, _, want_info = single.step(actions[world])
        for key in want_obs:
            assert_same(obs[key][world], want_obs[key], f"step {t} {key}")
        assert reward[world] == want_reward and info["distance"][world] == want_info["distance"]
        assert_same(env.unwrapped.get_state(world), single.unwrapped.get_state(), f"step {t} state")
    with pytest.raises(FetchError, match="shape"):
        env.unwrapped.set_state(0, np.zeros(3))
