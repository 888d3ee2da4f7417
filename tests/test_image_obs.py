"""Camera images in the observation (`cameras=`, `image_size=`): the dataset's images of the same state, bit
for bit; one per world in the vector env; nothing changes without them; the renderer goes on `close`."""

from __future__ import annotations

import pickle
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import SyncVectorEnv

import fetch
from fetch import rendering
from fetch.dataset import schema
from fetch.dataset.render.frames import StateRenderer
from fetch.errors import FetchError, UnknownNameError

TWO = ("front", "wrist")


class Spy:
    """Stands in for `rendering.OffscreenRenderer`: counts the renderers made and closed."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.made: list[Any] = []
        self.closed = 0
        real, spy = rendering.OffscreenRenderer, self

        class Counted(real):  # type: ignore[misc, valid-type]
            def __init__(self, *args: Any, **kwargs: Any) -> None:
                super().__init__(*args, **kwargs)
                spy.made.append(self)

            def close(self) -> None:
                spy.closed += 1
                super().close()

        monkeypatch.setattr(rendering, "OffscreenRenderer", Counted)


@pytest.mark.parametrize("env_id, quality, hide", [("PickPlace-v2", "full", False), ("Reach-v2", "fast", False),
                                                    ("Bin-pick-v2", "fast", False), ("PickPlace-v2", "fast", True)])
def test_images_are_the_ones_the_dataset_records_for_the_state(env_id: str, quality: str, hide: bool) -> None:
    """Reset, steps and set_state + observe: each image equals render-obs' (`StateRenderer`) of that state, at
    the same image quality, the goal's marker hidden in both where the env's kwargs say `hide_goal`."""
    kwargs: dict[str, Any] = {} if quality == rendering.DEFAULT_IMAGE_QUALITY else {"image_quality": quality}
    goal = {"hide_goal": True} if hide else {}
    env = gym.make(env_id, cameras=TWO, image_size=84, **kwargs, **goal)
    other = gym.make(env_id)  # a state from elsewhere, restored into the env with cameras
    other.reset(seed=9)
    other.action_space.seed(9)
    for _ in range(3):
        other.step(other.action_space.sample())
    with StateRenderer(env_id, goal, 84, 84, quality) as reference, StateRenderer(env_id, {}, 84, 84, quality) as shown:
        obs, _ = env.reset(seed=3)
        observed = [(obs, env.unwrapped.get_state())]
        for action in ([1.0, 0.5, -1.0, -1.0], [-0.5, 1.0, 1.0, 1.0]):
            obs, *_ = env.step(np.array(action, np.float32))
            observed.append((obs, env.unwrapped.get_state()))
        env.unwrapped.set_state(other.unwrapped.get_state())
        observed.append((env.unwrapped.observe()[0], other.unwrapped.get_state()))
        for obs, state in observed:
            assert env.observation_space.contains(obs)
            for camera in TWO:
                image = obs[schema.image_key(camera)]
                assert image.shape == (84, 84, 3) and image.dtype == np.uint8
                assert np.array_equal(image, reference.frame(state, camera))
                if hide and camera == "front":  # the goal's marker is in its view: hiding it changes the image
                    assert not np.array_equal(image, shown.frame(state, camera))
    assert not np.array_equal(observed[0][0]["front_image"], observed[-1][0]["front_image"])  # the images move
    env.close()
    other.close()


def test_fast_images_draw_the_same_scene_without_multisampling_or_reflection() -> None:
    """The two qualities differ (edges, the room floor's reflection) but show the same scene; making a fast
    renderer leaves the model's multisampling as it was, for the env's other renderers."""
    env = gym.make("Bin-pick-v2", cameras=("front",), image_size=64)
    base: Any = env.unwrapped
    samples = int(base.model.vis.quality.offsamples)
    fast = env.reset(seed=2)[0]["front_image"]
    assert int(base.model.vis.quality.offsamples) == samples > 0
    with StateRenderer("Bin-pick-v2", {}, 64, 64, "full") as full:
        sharp = full.frame(base.get_state(), "front")
    differ = np.any(fast != sharp, axis=-1)
    assert 0 < differ.mean() < 0.5
    assert np.abs(fast.astype(int) - sharp.astype(int)).mean() < 10
    env.close()


def test_a_bad_image_quality_is_one_line_naming_the_choices() -> None:
    with pytest.raises(FetchError, match=r"^image_quality 'best': choose one of fast, full$"):
        gym.make("Reach-v2", cameras=("front",), image_quality="best")


def test_the_image_keys_are_the_dataset_s() -> None:
    env = gym.make("Reach-v2", cameras=("wrist", "side"), image_size=32)
    obs, _ = env.reset(seed=0)
    assert set(obs) == {"observation", "achieved_goal", "desired_goal", "wrist_image", "side_image"}
    assert env.observation_space["side_image"] == gym.spaces.Box(0, 255, (32, 32, 3), np.uint8)
    assert obs["wrist_image"].std() > 5 and not np.shares_memory(obs["wrist_image"], obs["side_image"])
    env.close()


def test_without_cameras_nothing_changes_and_nothing_renders(monkeypatch: pytest.MonkeyPatch) -> None:
    spy = Spy(monkeypatch)
    plain, seeing = gym.make("PickPlace-v2"), gym.make("PickPlace-v2", cameras=("front",), image_size=32)
    assert set(plain.observation_space.spaces) == {"observation", "achieved_goal", "desired_goal"}
    runs, made = [], []
    for env in (plain, seeing):
        obs, _ = env.reset(seed=4)
        run = [obs]
        for action in ([1.0, 0.0, -1.0, -1.0], [0.0, 1.0, 0.5, 1.0]):
            run.append(env.step(np.array(action, np.float32))[0])
        runs.append(run)
        made.append(len(spy.made))
    assert made == [0, 1]  # none for the env without cameras; one for the other, on first use
    for without, with_images in zip(*runs, strict=True):
        assert set(without) == {"observation", "achieved_goal", "desired_goal"}
        for key in without:  # rendering leaves the physics alone: the rest is bit-identical
            assert without[key].dtype == with_images[key].dtype
            assert np.array_equal(without[key], with_images[key])
    plain.close()
    seeing.close()


def test_the_renderer_is_made_on_first_use_and_released_on_close(monkeypatch: pytest.MonkeyPatch) -> None:
    spy = Spy(monkeypatch)
    env = gym.make("Reach-v2", cameras=TWO, image_size=32)
    assert spy.made == []  # made lazily: an env that is never reset costs no GL context
    env.reset(seed=0)
    env.step(env.action_space.sample())
    assert len(spy.made) == 1 and spy.closed == 0  # one renderer serves every camera
    env.close()
    assert spy.closed == 1
    env.close()  # a second close is harmless and closes nothing twice
    assert spy.closed == 1


def test_hide_goal_hides_the_marker_in_the_images() -> None:
    red = lambda im: (im[..., 0] > 150) & (im[..., 1] < 80) & (im[..., 2] < 80)  # noqa: E731
    images = {}
    for hide in (False, True):
        env = gym.make("Reach-v2", cameras=("front",), image_size=84, hide_goal=hide)
        images[hide] = env.reset(seed=0)[0]["front_image"]
        env.close()
    assert red(images[False]).sum() > 2
    assert red(images[True]).sum() < red(images[False]).sum()


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"cameras": ("front", "nose")}, "unknown camera 'nose'; known: front, side, behind, wrist"),
    ({"cameras": ("front", "wrist", "front")}, "cameras names front more than once; list each camera once, "
                                               "e.g. cameras=('front', 'wrist')"),
    ({"cameras": "front"}, "cameras must be a sequence of camera names, e.g. cameras=('front',)"),
    ({"cameras": ("front",), "image_size": 0}, "image_size must be a whole number of pixels from 1 to 2048, got 0"),
    ({"cameras": ("front",), "image_size": 4096}, "image_size must be a whole number of pixels from 1 to 2048"),
    ({"cameras": ("front",), "image_size": 8.5}, "image_size must be a whole number of pixels"),
    ({"image_size": -1}, "image_size must be a whole number of pixels"),
    ({"cameras": ("front",), "image_size": True}, "image_size must be a whole number of pixels, got True"),
])
def test_bad_image_options_are_refused_in_one_line(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(FetchError) as caught:
        gym.make("Reach-v2", **kwargs)
    assert message in str(caught.value) and "\n" not in str(caught.value)
    with pytest.raises(FetchError, match="camera|image_size"):  # the vector env's template checks the same
        fetch.make_vec("Reach-v2", 2, **kwargs)


def test_an_unknown_camera_is_an_unknown_name() -> None:
    with pytest.raises(UnknownNameError):
        gym.make("Reach-v2", cameras=("nose",))


def test_check_env_and_pickling_with_cameras() -> None:
    env = gym.make("Push-v2", cameras=TWO, image_size=32)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    assert [str(w.message) for w in caught if "infinity" not in str(w.message)] == []
    obs, _ = env.reset(seed=2)
    copied = pickle.loads(pickle.dumps(env.unwrapped))
    again, _ = copied.observe()
    assert again.keys() == obs.keys() and all(np.array_equal(again[k], obs[k]) for k in obs)
    copied.close()
    env.close()


@pytest.mark.parametrize("num_envs", [1, 3, 9])
def test_the_vector_env_s_images_are_each_world_s_single_env_images(num_envs: int) -> None:
    """Bit for bit as a SyncVectorEnv of `gym.make` envs with the same cameras, through an autoreset; 9 worlds
    on 3 threads: the template renders some and two helper threads the others, each in its own GL context."""
    kwargs = {"cameras": TWO, "image_size": 32}
    vec = fetch.make_vec("PickPlace-v2", num_envs, max_episode_steps=2, nthread=3, **kwargs)
    sync = SyncVectorEnv([lambda: gym.make("PickPlace-v2", max_episode_steps=2, **kwargs)] * num_envs)
    assert vec.single_observation_space == sync.single_observation_space
    assert vec.observation_space["wrist_image"] == gym.spaces.Box(0, 255, (num_envs, 32, 32, 3), np.uint8)
    ours, theirs = vec.reset(seed=7)[0], sync.reset(seed=7)[0]
    rng = np.random.default_rng(0)
    for t in range(4):  # the worlds reach the limit at step 2 and reset in step 3
        for key in theirs:
            assert ours[key].dtype == theirs[key].dtype and np.array_equal(ours[key], theirs[key]), (t, key)
        actions = rng.uniform(-1, 1, (num_envs, 4))
        ours, theirs = vec.step(actions)[0], sync.step(actions)[0]
    assert vec.observation_space.contains(ours)
    vec.close()
    sync.close()


def test_the_vector_env_releases_its_renderer_on_close(monkeypatch: pytest.MonkeyPatch) -> None:
    spy = Spy(monkeypatch)
    vec = gym.make_vec("Reach-v2", num_envs=2, vectorization_mode="vector_entry_point", cameras=("front",),
                       image_size=32)
    vec.reset(seed=0)
    vec.step(np.zeros((2, 4)))
    assert len(spy.made) == 1  # one renderer, in the template, renders every world
    vec.close()
    assert spy.closed == 1


def test_the_vector_env_s_render_threads_are_released_on_close(monkeypatch: pytest.MonkeyPatch) -> None:
    """8 worlds on 2 threads: the template's renderer and one helper thread's, both released by close. (Where
    mujoco has no `mujoco.batch`, before 4.0, the worlds step on one thread and the template draws them all.)"""
    import threading

    spy = Spy(monkeypatch)
    vec = fetch.make_vec("Reach-v2", 8, nthread=2, cameras=("front",), image_size=32)
    vec.reset(seed=0)
    vec.step(np.zeros((8, 4)))
    threads = vec.nthread  # type: ignore[attr-defined]  # 2, or 1 without mujoco.batch
    assert len(spy.made) == threads
    assert any(t.name.startswith("fetch-render") for t in threading.enumerate()) == (threads > 1)
    vec.close()
    assert spy.closed == threads
    assert not any(t.name.startswith("fetch-render") for t in threading.enumerate())


def test_every_way_of_recording_images_has_the_envs_default_size() -> None:
    """`cameras=` observations, `collect --cameras`, `generate --cameras` and `render-obs` on a dataset without
    images all draw at `camera_obs.DEFAULT_IMAGE_SIZE`, 64 x 64 (docs/rendering.md): a policy trained on one
    acts on the others' images without a flag."""
    from fetch.camera_obs import DEFAULT_IMAGE_SIZE
    from fetch.cli import _parser
    from fetch.generate.run import GenerateConfig
    from fetch.teleop.config import CollectConfig

    assert DEFAULT_IMAGE_SIZE == 64
    env = gym.make("Reach-v2", cameras=("front",))
    try:
        assert env.reset(seed=0)[0]["front_image"].shape == (64, 64, 3)
    finally:
        env.close()
    assert CollectConfig(env_id="Reach-v2").image_size == GenerateConfig(source="s", out="o", demos=1).image_size == 64
    parser = _parser()
    for argv in (["collect", "--env", "Reach-v2"], ["generate", "--source", "s", "--out", "o", "--demos", "1"]):
        assert parser.parse_args(argv).image_size == 64, argv
    assert parser.parse_args(["render-obs", "d", "--camera", "front"]).size is None  # the dataset's, else 64
