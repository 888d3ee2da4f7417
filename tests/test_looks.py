"""`looks="random"`: each episode's colours, lights and camera mounts drawn from its reset seed. The physics,
observations and task draws are those of "plain"; the images differ between seeds and repeat for a seed;
the vector env, the dataset's renderer (`render-obs`, `generate --looks`) and pickling draw the same looks."""

from __future__ import annotations

import pathlib
import pickle
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.vector import SyncVectorEnv

import fetch
from fetch import looks as looks_module
from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.dataset.render.frames import StateRenderer
from fetch.dataset.validation import require_valid
from fetch.errors import FetchError
from fetch.looks import Looks, painted_things
from test_generate import collect, gen_argv

TWO = ("front", "wrist")
SIZE = 32


def rollout(env: Any, seed: int, steps: int = 6) -> tuple[list[dict[str, np.ndarray]], list[np.ndarray]]:
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    seen, states = [obs], [env.unwrapped.get_state()]
    for _ in range(steps):
        obs, *_ = env.step(rng.uniform(-1, 1, 4))
        seen.append(obs)
        states.append(env.unwrapped.get_state())
    return seen, states


@pytest.mark.parametrize("env_id", ["PickPlace-v2", "Bin-place-v2", "Drawer-open-v2"])
def test_the_looks_change_the_images_and_nothing_else(env_id: str) -> None:
    """The same seeds and actions: the same states and vectors as "plain"; the images differ from plain, and
    between two seeds, and come back the same for the same seed (a second env)."""
    plain = gym.make(env_id, cameras=TWO, image_size=SIZE)
    drawn = gym.make(env_id, cameras=TWO, image_size=SIZE, looks="random")
    again = gym.make(env_id, cameras=TWO, image_size=SIZE, looks="random")
    p_obs, p_states = rollout(plain, 4)
    d_obs, d_states = rollout(drawn, 4)
    a_obs, _ = rollout(again, 4)
    o_obs, _ = rollout(again, 5)
    for p, d, a, s, t in zip(p_obs, d_obs, a_obs, p_states, d_states, strict=True):
        assert np.array_equal(s, t)
        for key in ("observation", "achieved_goal", "desired_goal"):
            assert np.array_equal(p[key], d[key]), key
        for key in ("front_image", "wrist_image"):
            assert np.array_equal(d[key], a[key]), key  # a seed's looks, again
            assert np.abs(d[key].astype(int) - p[key]).mean() > 2, key  # not the plain scene
    for key in ("front_image", "wrist_image"):
        assert np.abs(o_obs[0][key].astype(int) - d_obs[0][key]).mean() > 2, key  # another seed, other looks


def test_seedless_resets_draw_new_looks_and_the_seed_s_draw_is_for_seed() -> None:
    env = gym.make("Reach-v2", looks="random").unwrapped
    env.reset(seed=11)
    first = env.looks
    reference = Looks.for_seed(env.model, 11)
    assert np.array_equal(first.gain, reference.gain) and np.array_equal(first.camera_turn, reference.camera_turn)
    env.reset()
    assert not np.array_equal(env.looks.gain, first.gain)
    assert gym.make("Reach-v2").unwrapped.looks is None  # plain: nothing drawn


def test_the_robot_and_the_goal_marker_keep_their_colours() -> None:
    model = gym.make("Bin-pick-v2").unwrapped.model
    things = painted_things(model)
    names = {model.body(int(model.geom_bodyid[g])).name for g in things}
    assert names and not any(n.startswith(looks_module.ROBOT_PREFIX) or n == "goal" for n in names)
    assert any(model.geom(g).name == "table0" for g in things)
    robot = [g for g in range(model.ngeom) if model.body(int(model.geom_bodyid[g])).name.startswith("robot0:")]
    assert robot and not set(robot) & set(things)


def test_the_vector_env_draws_each_world_s_looks() -> None:
    """5 worlds on 2 threads, through an autoreset: bit for bit a SyncVectorEnv of `gym.make` envs."""
    kwargs = {"cameras": TWO, "image_size": SIZE, "looks": "random"}
    vec = fetch.make_vec("PickPlace-v2", 5, max_episode_steps=2, nthread=2, **kwargs)
    sync = SyncVectorEnv([lambda: gym.make("PickPlace-v2", max_episode_steps=2, **kwargs)] * 5)
    ours, theirs = vec.reset(seed=3)[0], sync.reset(seed=3)[0]
    rng = np.random.default_rng(1)
    for t in range(4):
        for key in ("front_image", "wrist_image"):
            assert np.array_equal(ours[key], theirs[key]), (t, key)
        assert not np.array_equal(ours["front_image"][0], ours["front_image"][1])
        actions = rng.uniform(-1, 1, (5, 4))
        ours, theirs = vec.step(actions)[0], sync.step(actions)[0]
    vec.close()
    sync.close()


def test_the_dataset_s_renderer_draws_a_state_with_its_episode_s_looks() -> None:
    kwargs = {"looks": "random"}
    env = gym.make("Bin-pick-v2", cameras=("front",), image_size=SIZE, **kwargs)
    obs, _ = env.reset(seed=21)
    state = env.unwrapped.get_state()
    with StateRenderer("Bin-pick-v2", kwargs, SIZE, SIZE, "fast") as renderer:
        assert np.array_equal(renderer.frames(state[None], "front", 21)[0], obs["front_image"])
        assert not np.array_equal(renderer.frames(state[None], "front", 22)[0], obs["front_image"])
        with pytest.raises(FetchError, match="reset seed"):
            renderer.frames(state[None], "front")
    with StateRenderer("Bin-pick-v2", {}, SIZE, SIZE, "fast") as plain:  # plain looks need no seed
        assert plain.looks(None) is None and plain.frames(state[None], "front").shape == (1, SIZE, SIZE, 3)


def test_pickling_keeps_the_episode_s_looks() -> None:
    env = gym.make("Reach-v2", cameras=("front",), image_size=SIZE, looks="random").unwrapped
    obs, _ = env.reset(seed=2)
    copy = pickle.loads(pickle.dumps(env))
    assert np.array_equal(copy.observe()[0]["front_image"], obs["front_image"])


@pytest.mark.parametrize("bad", ["wild", "Random", ""])
def test_an_unknown_looks_is_one_line_naming_the_choices(bad: str) -> None:
    with pytest.raises(FetchError, match="choose one of plain, random") as error:
        gym.make("Reach-v2", looks=bad)
    assert "\n" not in str(error.value)


def test_generate_looks_random_records_the_looks_render_obs_draws_again(tmp_path: pathlib.Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """`generate --looks random`: the dataset's env kwargs say so, and each demo's images are those of its
    reset seed's looks, as `render-obs` draws them again; a resume with other looks is refused."""
    source = collect("PickPlace-v2", tmp_path / "src")
    out = tmp_path / "out"
    argv = gen_argv(source, out, 2, "--workers", "1", "--stop-on-success", "--cameras", "front",
                    "--image-size", str(SIZE), "--looks", "random")
    assert main(argv) == 0
    with open_dataset(out) as ds:
        require_valid(ds)
        assert ds.env_kwargs.get("looks") == "random"
        seeds = [int(ds.attrs(n)["seed"]) for n in ds.demo_names]
        images = [ds.arrays(n)["obs/front_image"] for n in ds.demo_names]
    assert len(set(seeds)) == 2
    assert not np.array_equal(images[0][0], images[1][0])
    assert main(["render-obs", str(out), "--camera", "front", "--size", str(SIZE), "--overwrite",
                 "--workers", "1"]) == 0
    with open_dataset(out) as ds:
        for name, before in zip(ds.demo_names, images, strict=True):
            assert np.array_equal(ds.arrays(name)["obs/front_image"], before), name
    capsys.readouterr()
    assert main(gen_argv(source, out, 3, "--workers", "1", "--stop-on-success", "--cameras", "front",
                         "--image-size", str(SIZE), "--looks", "plain")) != 0
    assert "env_kwargs.looks: the dataset has 'random', this session (none)" in capsys.readouterr().err  # what differs
    with open_dataset(out) as ds:
        assert len(ds.demo_names) == 2


def test_painting_leaves_the_model_alone() -> None:
    env = gym.make("Box-open-v2", cameras=("front",), image_size=SIZE, looks="random").unwrapped
    before = (env.model.geom_rgba.copy(), env.model.mat_rgba.copy(), env.model.light_diffuse.copy(),
              env.model.cam_pos.copy())
    env.reset(seed=0)
    env.step(np.zeros(4))
    after = (env.model.geom_rgba, env.model.mat_rgba, env.model.light_diffuse, env.model.cam_pos)
    assert all(np.array_equal(a, b) for a, b in zip(before, after, strict=True))
    assert isinstance(env.model, mujoco.MjModel)
