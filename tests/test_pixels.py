"""The pixel policy (`gym-fetch train --inputs pixels`) on real data: it learns from the cameras' images, the
robot's own readings and the goal, and provably nothing else; it runs in eval, `fetch.learn.load` and the
collector, rendering its cameras as it goes."""

from __future__ import annotations

import pathlib
import re

import gymnasium as gym
import numpy as np
import pytest

from conftest import StretchCorrector, hide_objects, objects_state
from fetch.cli import main
from fetch.errors import FetchError

TINY = ["--hidden", "32", "--batch-size", "16", "--checkpoint-every", "10"]
SIZE = 16
"""[px] the images' side: small, so the tests are quick; the benchmark measures what the default 64 px learns."""


@pytest.fixture(scope="module")
def seen(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """6 PickPlace-v2 expert demos with front and wrist images."""
    out = tmp_path_factory.mktemp("pixels") / "pickplace"
    assert main(["collect", "--env", "PickPlace-v2", "--device", "expert", "--episodes", "6", "--render", "none",
                 "--max-steps", "50", "--cameras", "front,wrist", "--image-size", str(SIZE), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def blind_data(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """3 PickPlace-v2 expert demos without images."""
    out = tmp_path_factory.mktemp("pixels") / "state-only"
    assert main(["collect", "--env", "PickPlace-v2", "--device", "expert", "--episodes", "3", "--render", "none",
                 "--max-steps", "50", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def run(torch, seen: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:  # noqa: ANN001
    out = tmp_path_factory.mktemp("pixels") / "run"
    assert main(["train", str(seen), "--out", str(out), "--inputs", "pixels", "--steps", "30", *TINY]) == 0
    return out


def _train(dataset: pathlib.Path, out: pathlib.Path, *extra: str) -> int:
    return main(["train", str(dataset), "--out", str(out), *TINY, *extra])


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    """What the command said on stderr, but for the note a slow read of the dataset prints first."""
    return "\n".join(line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("reading "))


def test_a_pixel_policy_records_what_it_sees(torch, run: pathlib.Path) -> None:  # noqa: ANN001
    from fetch.learn.data import PROPRIOCEPTION, unseen_by_pixels, velocity_columns

    state = torch.load(run / "checkpoint.pt", weights_only=True)
    policy = state["policy"]
    assert policy["kind"] == "cnn-chunk" and tuple(policy["cameras"]) == ("front", "wrist")
    assert policy["image_size"] == SIZE and policy["image_quality"] == "fast"  # the data's (collect's default)
    layout = gym.make("PickPlace-v2").unwrapped.observation_layout
    readings = {i for name in PROPRIOCEPTION for i in range(layout[name].start, layout[name].stop)}
    velocities = set(velocity_columns(layout))  # PickPlace's line: not seen, by a pixel policy either
    assert set(policy["blind"]) == set(unseen_by_pixels(layout, policy["goal_offsets"])) | velocities
    positions = readings - velocities  # the hand's position, the fingers' opening
    assert positions and set(range(25)) - set(policy["blind"]) == positions  # the goal (25-27) stays seen
    assert not {25, 26, 27} & set(policy["blind"])


def test_the_pixel_policy_acts_the_same_with_the_objects_state_replaced_by_nan(torch, run: pathlib.Path) -> None:  # noqa: ANN001
    """The proof it sees: every entry of the state observation but the robot's own readings (and the
    achieved goal: the object's position) set to NaN gives the same actions, step after step of an
    episode; other images give other actions."""
    import fetch.learn
    policy = fetch.learn.load(run)
    assert policy.observation_kwargs == {"cameras": ("front", "wrist"), "image_size": SIZE, "image_quality": "fast"}
    env = gym.make(policy.env_id, **policy.env_kwargs, **policy.observation_kwargs)
    hidden = objects_state(env.unwrapped.observation_layout)
    obs, _ = env.reset(seed=2024)
    policy.reset()
    twin = fetch.learn.load(run)
    twin.reset()
    for _ in range(8):
        action = policy(obs)
        assert np.isfinite(action).all()
        np.testing.assert_array_equal(twin(hide_objects(obs, hidden)), action)
        obs, *_ = env.step(action)
    other = {**obs, "front_image": np.zeros_like(obs["front_image"]), "wrist_image": 255 - obs["wrist_image"]}
    policy.reset()
    twin.reset()
    assert not np.array_equal(policy(obs), twin(other))
    env.close()


def test_the_policy_asks_for_its_cameras_in_one_line(torch, run: pathlib.Path) -> None:  # noqa: ANN001
    import fetch.learn

    policy = fetch.learn.load(run)
    obs, _ = gym.make("PickPlace-v2").reset(seed=1)
    with pytest.raises(FetchError, match=r"sees front_image, wrist_image, which the observation lacks.*"
                                         r"observation_kwargs"):
        policy(obs)
    bigger = gym.make("PickPlace-v2", cameras=("front", "wrist"), image_size=SIZE + 8)
    obs, _ = bigger.reset(seed=1)
    policy.reset()
    with pytest.raises(FetchError, match=rf"learnt from uint8 \({SIZE}, {SIZE}, 3\) images"):
        policy(obs)
    bigger.close()


def test_eval_renders_the_cameras_of_a_pixel_policy(torch, run: pathlib.Path) -> None:  # noqa: ANN001
    """eval's batched envs give the policy its images; the result equals one env's, episode by episode."""
    import fetch.learn
    from fetch.learn.evaluate import eval_seeds, evaluate

    policy = fetch.learn.load(run)
    result = evaluate(policy, 2, envs=2)
    assert result.episodes == 2
    env = gym.make(policy.env_id, max_episode_steps=policy.horizon, **policy.env_kwargs, **policy.observation_kwargs)
    for seed, success in zip(eval_seeds(2, policy.seeds), result.success, strict=True):
        obs, _ = env.reset(seed=seed)
        policy.reset()
        for _ in range(policy.horizon):
            obs, _, _, _, info = env.step(policy(obs))
        assert bool(info["is_success"]) == success
    env.close()


def test_eval_looks_random_draws_each_episode_s_looks_for_the_policy(torch, run: pathlib.Path,  # noqa: ANN001
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """`eval --looks random`: the episodes' envs draw their looks (the training data's were plain), so the
    policy's first actions differ from plain's on the same seeds; an unknown choice is argparse's error."""
    import fetch.learn
    from fetch.learn import evaluate as evaluate_module

    made: list[dict[str, object]] = []
    real = evaluate_module.make_vector_env

    def spy(env_id: str, count: int, env_kwargs: dict[str, object], *args: object) -> object:
        made.append(dict(env_kwargs))
        return real(env_id, count, env_kwargs, *args)

    monkeypatch.setattr(evaluate_module, "make_vector_env", spy)
    assert main(["eval", str(run), "--episodes", "2", "--envs", "2", "--looks", "random"]) == 0
    assert made[-1]["looks"] == "random"
    policy = fetch.learn.load(run)
    assert "looks" not in policy.env_kwargs  # recorded plain
    first = []
    for looks in ("plain", "random"):
        env = gym.make(policy.env_id, **policy.env_kwargs, **policy.observation_kwargs, looks=looks)
        obs, _ = env.reset(seed=5)
        policy.reset()
        first.append(policy(obs))
        env.close()
    assert not np.array_equal(first[0], first[1])
    with pytest.raises(SystemExit):
        main(["eval", str(run), "--looks", "wild"])


def test_a_pixel_policy_drives_a_collection_session_seeing_what_the_env_shows(torch, run: pathlib.Path,  # noqa: ANN001
                                                                            tmp_path: pathlib.Path) -> None:
    """`collect --device policy` with a pixel policy: the device renders the cameras from the state the
    collector's env is in (an env without cameras), and acts as the policy does on the env's own images."""
    import fetch.learn
    from fetch.dataset import open_dataset
    from fetch.learn.device import PolicyDevice
    from fetch.teleop.session import CollectConfig, Session

    plain = gym.make("PickPlace-v2", max_episode_steps=50)
    device = PolicyDevice(plain, run)
    seeing = gym.make("PickPlace-v2", cameras=("front", "wrist"), image_size=SIZE)
    policy = fetch.learn.load(run)
    obs, _ = plain.reset(seed=77)
    with_images, _ = seeing.reset(seed=77)
    device.reset()
    policy.reset()
    for _ in range(5):
        action = device.poll(obs).action
        np.testing.assert_array_equal(action, policy(with_images))
        obs, *_ = plain.step(action)
        with_images, *_ = seeing.step(action)
    device.close()
    seeing.close()
    config = CollectConfig(env_id="PickPlace-v2", out=str(tmp_path / "demos"), episodes=1, max_steps=20,
                           device="expert", render="none", keep_failures=True, seed=500)
    env = gym.make("PickPlace-v2", max_episode_steps=20)
    Session(config, PolicyDevice(env, run), log=lambda _: None).run()
    with open_dataset(tmp_path / "demos") as ds:
        (name,) = ds.demo_names
        assert int(ds.attrs(name)["num_samples"]) > 0


def test_a_person_corrects_a_camera_policy_and_it_learns_from_the_correction(torch, run: pathlib.Path,  # noqa: ANN001
                                                                             seen: pathlib.Path,
                                                                             tmp_path: pathlib.Path) -> None:
    """A correction round with a camera policy: `collect --device takeover` records the cameras the policy sees
    while a person takes over stretch by stretch, and `train --from` goes on learning the camera policy from the
    demos plus the stretches the person drove, from their images."""
    from fetch.dataset import open_dataset, validate
    from fetch.learn import load
    from fetch.learn.device import PolicyDevice
    from fetch.learn.takeover import TakeoverDevice
    from fetch.teleop.session import CollectConfig, Session

    corrected = tmp_path / "corrected"
    env = gym.make("PickPlace-v2", max_episode_steps=30)
    config = CollectConfig(env_id="PickPlace-v2", out=str(corrected), episodes=2, max_steps=30, device="takeover",
                           render="none", control_hz=0, keep_failures=True, seed=800, cameras=("front", "wrist"),
                           image_size=SIZE)
    Session(config, TakeoverDevice(PolicyDevice(env, run), StretchCorrector()), env=env, log=lambda _: None).run()
    with open_dataset(corrected) as ds:
        assert validate(ds) == []
        arrays = [ds.arrays(n) for n in ds.demo_names]
    assert all(0 < a["intervention"].sum() < len(a["intervention"]) for a in arrays), "both drove in each"
    assert all(a["obs/front_image"].shape[1:] == (SIZE, SIZE, 3) for a in arrays)
    again = tmp_path / "again"
    assert main(["train", str(seen), str(corrected), "--from", str(run), "--out", str(again), "--steps", "10",
                 "--batch-size", "16"]) == 0
    policy, base = load(again), load(run)
    assert policy.config == base.config and policy.config.cameras == ("front", "wrist")
    assert policy.trained_steps == 10
    state = torch.load(again / "checkpoint.pt", weights_only=True)
    assert any(name.endswith("(takeover 1)") for name in state["source"]["train_demos"]), "the corrected stretches"


def test_a_pixel_run_resumes_to_the_uninterrupted_result(torch, seen: pathlib.Path, tmp_path: pathlib.Path) -> None:  # noqa: ANN001
    """The random shifts come from torch's generator, which the checkpoint keeps: a run stopped after its
    checkpoint at step 10 and run again ends with the weights of one that was never stopped."""
    from fetch.learn.settings import TrainRequest
    from fetch.learn.train import train

    request = TrainRequest(inputs="pixels", steps=20, hidden=32, batch_size=16, checkpoint_every=10)

    def stop_at_the_first_checkpoint(line: str) -> None:
        if line.startswith("step 10/20: train loss"):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(seen, tmp_path / "parts", request, show_progress=False, log=stop_at_the_first_checkpoint)
    assert torch.load(tmp_path / "parts" / "checkpoint.pt", weights_only=True)["step"] == 10
    assert train(seen, tmp_path / "parts", request, show_progress=False, log=lambda _: None).resumed_from == 10
    train(seen, tmp_path / "whole", request, show_progress=False, log=lambda _: None)
    parts, whole = (torch.load(tmp_path / r / "checkpoint.pt", weights_only=True)["model"] for r in ("parts", "whole"))
    assert parts.keys() == whole.keys() and all(bool((parts[k] == whole[k]).all()) for k in whole)


@pytest.mark.parametrize(("argv", "message"), [
    (["--inputs", "pixels", "--policy", "mlp-chunk"], "--policy mlp-chunk sees the state, not pixels"),
    (["--inputs", "pixels", "--cameras", "side"], "--cameras side: .* has images of front, wrist only"),
    (["--inputs", "pixels", "--mirror"], "--mirror does not apply to a pixel policy"),
    (["--cameras", "front"], "--cameras is for a pixel policy"),
])
def test_bad_pixel_requests_get_one_line_errors(torch, seen: pathlib.Path, tmp_path, capsys, argv,  # noqa: ANN001
                                                message: str) -> None:
    assert _train(seen, tmp_path / "run", "--steps", "5", *argv) == 2
    err = _error(capsys)
    assert len(err.splitlines()) == 1 and re.search(message, err), err
    assert not (tmp_path / "run").exists()


def test_pixels_from_a_dataset_without_images_says_how_to_make_them(torch, blind_data: pathlib.Path, tmp_path,  # noqa: ANN001
                                                                   capsys) -> None:
    assert _train(blind_data, tmp_path / "run", "--inputs", "pixels", "--steps", "5") == 2
    err = _error(capsys)
    assert len(err.splitlines()) == 1 and "holds no camera images" in err and "render-obs" in err, err


def test_a_pixel_run_takes_its_kinds_training_defaults_unless_told(seen: pathlib.Path) -> None:
    """`--inputs pixels` (or `--policy cnn-chunk`) trains with the pixel kind's steps, batch and threads (one
    per core), seeing every camera the dataset has; flags given override them. No torch needed to plan."""
    from fetch.dataset.habits import layout_of
    from fetch.learn.data import load_demos, velocity_columns
    from fetch.learn.kinds import FINGER_SCALE, kind
    from fetch.learn.settings import TrainRequest, cores, plan

    demos = load_demos(seen, images=True)
    own = kind("cnn-chunk").training
    for request in (TrainRequest(inputs="pixels"), TrainRequest(policy="cnn-chunk")):
        chosen = plan(request, demos)
        assert chosen.policy.kind == "cnn-chunk" and chosen.policy.cameras == ("front", "wrist")
        assert (chosen.config.steps, chosen.config.batch_size) == (own["steps"], own["batch_size"])
        assert chosen.config.threads == cores() and not chosen.config.mirror
        assert chosen.config.precision == "auto"  # decided by train, which knows the device
    told = plan(TrainRequest(inputs="pixels", steps=7, batch_size=5, threads=1, cameras=("wrist",), precision="fp32"),
                demos)
    assert (told.config.steps, told.config.batch_size, told.config.threads, told.config.precision) == (7, 5, 1, "fp32")
    assert told.policy.cameras == ("wrist",)
    state = plan(TrainRequest(policy="mlp-chunk"), demos)
    assert (state.config.batch_size, state.config.threads, state.policy.cameras) == (256, 1, ())
    assert state.config.precision == "fp32"
    # PickPlace's line in the task table: neither a state policy nor a pixel policy sees velocities (what
    # each measured best from demos with rests in them), unless told.
    layout = layout_of(demos.env_id)
    velocities = set(velocity_columns(layout))
    own_velocities = {i for name in ("grip_velp", "gripper_vel") for i in range(layout[name].start, layout[name].stop)}
    assert velocities <= set(plan(TrainRequest(), demos).policy.blind)
    assert own_velocities <= set(plan(TrainRequest(inputs="pixels"), demos).policy.blind)
    assert not own_velocities & set(plan(TrainRequest(inputs="pixels", velocities=True), demos).policy.blind)
    assert not velocities & set(plan(TrainRequest(velocities=True), demos).policy.blind)
    # The pixel policy learns the fingers' action companded, as the state kinds do, unless told.
    assert plan(TrainRequest(inputs="pixels"), demos).policy.finger_scale == FINGER_SCALE > 0
    assert plan(TrainRequest(inputs="pixels", finger_scale=0.0), demos).policy.finger_scale == 0.0


def test_auto_precision_is_bf16_where_the_cpu_computes_it_natively(torch, run: pathlib.Path,  # noqa: ANN001
                                                                   seen: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """The run records what auto became; --precision fp32 trains in fp32; a bad one is a one-line error."""
    from fetch.learn.settings import TrainConfig
    from fetch.learn.train import CPU, native_bf16

    trained = torch.load(run / "checkpoint.pt", weights_only=True)["train"]
    assert trained["precision"] == ("bf16" if native_bf16(CPU) else "fp32")
    assert _train(seen, tmp_path / "fp32", "--inputs", "pixels", "--steps", "3", "--precision", "fp32") == 0
    assert torch.load(tmp_path / "fp32" / "checkpoint.pt", weights_only=True)["train"]["precision"] == "fp32"
    with pytest.raises(FetchError, match=r"^--precision 'fp16': choose one of auto, fp32, bf16$"):
        TrainConfig(precision="fp16")


def test_asking_for_cuda_where_there_is_none_is_one_line(torch, seen: pathlib.Path, tmp_path, capsys) -> None:  # noqa: ANN001
    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA device")
    assert _train(seen, tmp_path / "run", "--inputs", "pixels", "--steps", "5", "--accelerator", "cuda") == 2
    err = _error(capsys)
    assert len(err.splitlines()) == 1 and "--accelerator cuda: torch sees no CUDA device" in err, err


def test_a_pixel_policy_saved_before_image_quality_was_recorded_sees_full_images(
        torch, run: pathlib.Path, tmp_path: pathlib.Path) -> None:  # noqa: ANN001
    """Its images were drawn at "full", the only quality there was: it is run, and goes on training, so."""
    import io

    import fetch.learn
    from fetch.learn import checkpoint

    state = torch.load(run / "checkpoint.pt", weights_only=True)
    del state["policy"]["image_quality"]
    old = tmp_path / "old"
    old.mkdir()
    buffer = io.BytesIO()
    torch.save(state, buffer)
    checkpoint.write(old, buffer.getvalue())
    policy = fetch.learn.load(old)
    assert policy.observation_kwargs["image_quality"] == "full"
    env = gym.make(policy.env_id, **policy.env_kwargs, **policy.observation_kwargs)
    obs, _ = env.reset(seed=5)
    assert np.isfinite(policy(obs)).all()
    env.close()
