"""Our tasks as a LeRobot environment (plugins/lerobot_env_fetch, `--env.type=fetch`), checked with lerobot itself.

Runs where lerobot >= 0.6 and the plugin are installed (Python 3.12; docs/lerobot_env.md), skipped elsewhere:
every id through lerobot's own `make_env` and `preprocess_observation`; the env's keys, shapes and first
values equal those `gym-fetch export --to lerobot` writes, for a state and a camera policy; and the real
`lerobot-train` / `lerobot-eval` console scripts train on an export and evaluate it in the env.
"""

from __future__ import annotations

import ast
import json
import os
import pathlib
import subprocess
import sys
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("lerobot.envs.configs", reason="lerobot >= 0.6 is not installed (docs/lerobot_env.md)")
pytest.importorskip("lerobot_env_fetch", reason="the plugin is not installed: pip install -e plugins/lerobot_env_fetch")
pq = pytest.importorskip("pyarrow.parquet")
av = pytest.importorskip("av")

from lerobot.envs.factory import make_env, make_env_config  # noqa: E402
from lerobot.envs.utils import env_to_policy_features, preprocess_observation  # noqa: E402
from lerobot.utils.feature_utils import dataset_to_policy_features  # noqa: E402
from lerobot.utils.import_utils import register_third_party_plugins  # noqa: E402

import fetch  # noqa: E402
from conftest import expert_demos  # noqa: E402
from fetch.cli import main  # noqa: E402
from fetch.dataset.exports import lerobot as export  # noqa: E402

SIZE = 64
CAMERAS = {"state": "none", "camera": "front,wrist"}
"""The two kinds of policy: `--env.cameras` (and the export's `--cameras`) of each."""
BIN = pathlib.Path(sys.executable).parent


def vector_env(task: str, cameras: str, **kwargs: object):  # noqa: ANN201 (a gymnasium VectorEnv)
    cfg = make_env_config("fetch", task=task, cameras=cameras, image_size=SIZE, **kwargs)
    return cfg, make_env(cfg, n_envs=1, use_async_envs=False)["fetch"][0]


def test_lerobot_finds_the_plugin() -> None:
    from lerobot.configs import PreTrainedConfig
    from lerobot.envs.configs import EnvConfig
    from lerobot.policies.factory import get_policy_class

    register_third_party_plugins()  # what lerobot-train, lerobot-eval and lerobot-record call
    assert "fetch" in EnvConfig.get_known_choices()
    assert "gym_fetch" in PreTrainedConfig.get_known_choices()  # a gym-fetch train run (export_policy)
    assert get_policy_class("gym_fetch").__name__ == "GymFetchPolicy"


@pytest.mark.parametrize("kind", list(CAMERAS))
@pytest.mark.parametrize("task", fetch.ENV_IDS)
def test_every_id_runs_as_lerobot_sees_it(task: str, kind: str) -> None:
    cfg, env = vector_env(task, CAMERAS[kind])
    try:
        declared = {k: tuple(f.shape) for k, f in env_to_policy_features(cfg).items() if k != "action"}
        obs, info = env.reset(seed=[7])
        assert info["is_success"].dtype == bool
        for _ in range(3):
            batch = preprocess_observation(obs)
            assert {k: tuple(v.shape[1:]) for k, v in batch.items()} == declared
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            assert info["is_success"].dtype == bool and info["is_success"].shape == (1,)
        plain = fetch_env(task)
        state = 10 if kind == "camera" else plain.observation_space["observation"].shape[0]
        assert declared["observation.state"] == (state,)
        assert env.call("task_description") == (plain.task.instruction,)
        plain.close()
        assert env.call("_max_episode_steps") == (50,)
        assert env.metadata["render_fps"] == cfg.fps == 25
    finally:
        env.close()


def fetch_env(task: str):  # noqa: ANN201
    return gym.make(task).unwrapped


def test_seeds_are_honoured() -> None:
    _, env = vector_env("PickPlace-v2", "none")
    try:
        first = [env.reset(seed=[s])[0]["agent_pos"].copy() for s in (3, 3, 4)]
    finally:
        env.close()
    assert np.array_equal(first[0], first[1]) and not np.array_equal(first[0], first[2])


def test_episode_length_is_an_option() -> None:
    _, env = vector_env("Reach-v2", "none", episode_length=7)
    try:
        assert env.call("_max_episode_steps") == (7,)
    finally:
        env.close()


def test_success_ends_the_episode_and_is_reported() -> None:
    import lerobot_env_fetch

    env = lerobot_env_fetch.make("Reach-v2", cameras=())
    obs, info = env.reset(seed=0)
    assert info["is_success"] is False
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated):  # toward the goal, read from the observation (Reach: no object)
        move = np.clip((obs["environment_state"] - obs["agent_pos"][:3]) * 20, -1, 1)
        obs, _, terminated, truncated, info = env.step(np.append(move, 0.0).astype(np.float32))
        assert isinstance(info["is_success"], bool) and terminated == info["is_success"]
        steps += 1
    env.close()
    assert terminated and steps < 50
    with lerobot_env_fetch.make("Reach-v2", terminate_on_success=False) as env:
        env.reset(seed=0)
        assert not any(env.step(np.zeros(4, np.float32))[2] for _ in range(5))


@pytest.fixture(scope="module")
def pick_demos(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Two PickPlace-v2 expert demos (a task whose observation holds the block, unlike Reach's)."""
    return expert_demos(tmp_path_factory, "PickPlace-v2", 2)


@pytest.fixture(scope="module")
def exports(pick_demos: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, pathlib.Path]:
    root = tmp_path_factory.mktemp("exports")
    for kind, cameras in CAMERAS.items():
        assert main(["export", str(pick_demos), "--to", "lerobot", "--repo-id", f"local/pick_{kind}", "--out",
                     str(root / kind), "--cameras", cameras, "--image-size", str(SIZE)]) == 0
    return {kind: root / kind for kind in CAMERAS}


@pytest.mark.parametrize("kind", list(CAMERAS))
def test_env_gives_what_the_export_declares(kind: str, exports: dict[str, pathlib.Path]) -> None:
    """Keys and shapes as lerobot reads them from the export, and the first frame's values."""
    root = exports[kind]
    info = json.loads((root / "meta/info.json").read_text())
    from_export = {k: tuple(f.shape) for k, f in dataset_to_policy_features(info["features"]).items()
                   if k.startswith("observation.")}
    cfg, env = vector_env("PickPlace-v2", CAMERAS[kind])
    try:
        from_env = {k: tuple(f.shape) for k, f in env_to_policy_features(cfg).items() if k != "action"}
        assert from_env == from_export
        episodes = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
        obs, _ = env.reset(seed=[episodes[0]["gym_fetch/seed"]])
        got = {k: v[0].numpy() for k, v in preprocess_observation(obs).items()}
    finally:
        env.close()
    row = pq.read_table(root / "data/chunk-000/file-000.parquet").slice(0, 1).to_pylist()[0]
    names = info["features"]["observation.state"]["names"]
    if kind == "camera":  # the robot's own readings only: no block pose handed to a policy that sees
        assert len(names) == 10 and all(n.startswith(export.ROBOT_PARTS) for n in names)
    assert np.array_equal(got["observation.state"], np.asarray(row["observation.state"], np.float32))
    assert np.array_equal(got["observation.environment_state"],
                          np.asarray(row["observation.environment_state"], np.float32))
    for camera in CAMERAS[kind].split(",") if kind == "camera" else ():
        key = f"observation.images.{camera}"
        with av.open(str(root / f"videos/{key}/chunk-000/file-000.mp4")) as container:
            frame = next(container.decode(video=0)).to_ndarray(format="rgb24").astype(np.float64)
        mse = np.mean((got[key].transpose(1, 2, 0) * 255 - frame) ** 2)
        assert 10 * np.log10(255**2 / max(mse, 1e-12)) > 30  # H.264 of the same picture


def run(*argv: str, cwd: pathlib.Path) -> str:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_LEROBOT_HOME": str(cwd / "hf"), "WANDB_MODE": "disabled"}
    done = subprocess.run([str(BIN / argv[0]), *argv[1:]], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done.stdout + done.stderr


TINY_ACT = ["--policy.type=act", "--policy.device=cpu", "--policy.push_to_hub=false", "--policy.dim_model=32",
            "--policy.n_heads=2", "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1",
            "--policy.n_decoder_layers=1", "--policy.chunk_size=5", "--policy.n_action_steps=5",
            "--policy.use_vae=false", "--policy.pretrained_backbone_weights=null"]


@pytest.mark.parametrize("kind", list(CAMERAS))
def test_lerobot_eval_runs_a_policy_trained_on_an_export(kind: str, exports: dict[str, pathlib.Path],
                                                         tmp_path: pathlib.Path) -> None:
    """The console scripts as a user runs them: lerobot-train on the export, then lerobot-eval in the env with
    no renaming; it reports pc_success and writes a video of each episode."""
    run("lerobot-train", f"--dataset.repo_id=local/pick_{kind}", f"--dataset.root={exports[kind]}", *TINY_ACT,
        "--steps=2", "--batch_size=2", "--save_freq=2", "--num_workers=0", f"--output_dir={tmp_path / 'train'}",
        cwd=tmp_path)
    out = run("lerobot-eval", f"--policy.path={tmp_path / 'train/checkpoints/last/pretrained_model'}",
              "--env.type=fetch", "--env.task=PickPlace-v2", f"--env.cameras={CAMERAS[kind]}",
              f"--env.image_size={SIZE}", "--env.video_size=64", "--eval.n_episodes=2", "--eval.batch_size=1",
              "--policy.device=cpu", f"--output_dir={tmp_path / 'eval'}", cwd=tmp_path)
    assert "pc_success" in out
    overall = json.loads((tmp_path / "eval/eval_info.json").read_text())["overall"]
    assert overall["n_episodes"] == 2 and 0 <= overall["pc_success"] <= 100
    assert len(overall["video_paths"]) == 2 and all(pathlib.Path(p).stat().st_size > 0 for p in overall["video_paths"])


def evaluated(log: str) -> dict[int, dict]:
    """lerobot-train's in-training evaluations, by step: what its 'Suite overall aggregated' line holds."""
    steps = [int(line.rsplit(" ", 1)[1]) for line in log.splitlines() if "Eval policy at step" in line]
    overall = [ast.literal_eval(line.split("Suite overall aggregated: ", 1)[1]) for line in log.splitlines()
               if "Suite overall aggregated: " in line]
    assert len(steps) == len(overall), log[-3000:]
    return dict(zip(steps, overall, strict=True))


def test_lerobot_train_resumes_and_evaluates_in_the_env(exports: dict[str, pathlib.Path],
                                                        tmp_path: pathlib.Path) -> None:
    """lerobot-train on an export, on the CPU, evaluating in the env every 2 steps (`--env.type=fetch
    --env_eval_freq=2`); stopped at step 2 and resumed from its checkpoint to step 4, it goes on from step 2."""
    out = tmp_path / "train"
    first = run("lerobot-train", "--dataset.repo_id=local/pick_state", f"--dataset.root={exports['state']}",
                *TINY_ACT, "--steps=2", "--batch_size=2", "--save_freq=2", "--num_workers=0", f"--output_dir={out}",
                "--env.type=fetch", "--env.task=PickPlace-v2", "--env.cameras=none", "--env.video_size=64",
                "--env_eval_freq=2", "--eval.n_episodes=1", "--eval.batch_size=1", "--wandb.enable=false",
                cwd=tmp_path)
    config = out / "checkpoints/last/pretrained_model/train_config.json"
    resumed = run("lerobot-train", "--resume=true", f"--config_path={config}", "--steps=4", cwd=tmp_path)
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["000002", "000004", "last"]
    state = json.loads((out / "checkpoints/000004/training_state/training_step.json").read_text())
    assert state["step"] == 4
    # The resumed run trained steps 3 and 4 only: a run started afresh would have evaluated at step 2 as well.
    for log, step in ((first, 2), (resumed, 4)):
        evals = evaluated(log)
        assert list(evals) == [step], evals
        assert evals[step]["n_episodes"] == 1 and 0 <= evals[step]["pc_success"] <= 100
        (video,) = evals[step]["video_paths"]
        assert pathlib.Path(video).is_relative_to(out / f"eval/videos_step_{step:06d}")
        assert pathlib.Path(video).stat().st_size > 0


def test_lerobot_eval_runs_a_gym_fetch_run(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """A `gym-fetch train` run, written as a LeRobot policy (`export_policy`), evaluated by lerobot-eval in
    the env with the command the export prints: on `gym-fetch eval`'s seeds every episode ends as it does
    there. LeRobot's pc_success counts an episode that succeeded at any step, `gym-fetch eval`'s "succeeded
    at some step" (its headline rate is success at the last step)."""
    from lerobot_env_fetch import export_policy

    from fetch.learn.evaluate import evaluate
    from fetch.learn.runtime import load

    assert main(["train", str(reach_demos), "--out", str(tmp_path / "run"), "--steps", "50", "--hidden", "32",
                 "--batch-size", "64"]) == 0
    capsys.readouterr()
    assert export_policy.main([str(tmp_path / "run"), str(tmp_path / "policy")]) == 0
    command = capsys.readouterr().out.splitlines()[-1].split()
    assert command[:2] == ["lerobot-eval", f"--policy.path={tmp_path / 'policy'}"] and "--seed=1000000" in command
    episodes = ["--eval.n_episodes=4", "--eval.batch_size=2", "--env.video_size=64",
                f"--output_dir={tmp_path / 'eval'}"]
    assert "pc_success" in run(*[a for a in command if not a.startswith("--eval.n_episodes")], *episodes, cwd=tmp_path)
    info = json.loads((tmp_path / "eval/eval_info.json").read_text())
    (task,) = info["per_task"]
    assert main(["eval", str(tmp_path / "run"), "--episodes", "4", "--envs", "2",
                 "--json", str(tmp_path / "ours.json")]) == 0
    ours = json.loads((tmp_path / "ours.json").read_text())
    assert ours["seeds"] == list(range(1_000_000, 1_000_004))
    assert info["overall"]["pc_success"] == pytest.approx(100 * ours["ever_success_rate"])
    assert task["metrics"]["successes"] == list(evaluate(load(tmp_path / "run"), 4, envs=2).ever)
    # Step by step: the LeRobot policy's action is the run's own, bit for bit, on what each env gives.
    from lerobot_env_fetch.modeling_gym_fetch import GymFetchPolicy

    wrapped, ours = GymFetchPolicy.from_pretrained(tmp_path / "policy"), load(tmp_path / "run")
    _, env = vector_env("Reach-v2", "none", terminate_on_success=False)
    _act_in_lockstep(wrapped, ours, env, gym.make("Reach-v2"), seed=5, steps=50)


def _act_in_lockstep(wrapped: Any, ours: Any, env: Any, plain: gym.Env, seed: int, steps: int) -> None:
    """Step LeRobot's env with the wrapped policy and our env with the run's own, from one seed and with the
    same actions: the wrapped policy's action must be the run's, bit for bit, at every step."""
    try:
        obs, _ = env.reset(seed=[seed])
        raw, _ = plain.reset(seed=seed)
        wrapped.reset()
        ours.reset()
        for _ in range(steps):
            action = wrapped.select_action(preprocess_observation(obs)).numpy()
            assert np.array_equal(action[0], ours(raw))
            obs, *_ = env.step(action)
            raw, *_ = plain.step(action[0])
    finally:
        env.close()
        plain.close()


def test_a_camera_policy_reads_back_what_our_env_gives() -> None:
    """LeRobot's batch from the env with cameras, turned back into our observation: the robot's readings
    in their places (the rest 0: a camera policy does not see it), the goal, and the images exactly."""
    from lerobot_env_fetch.modeling_gym_fetch import Inputs

    plain = gym.make("PickPlace-v2", cameras=("front",), image_size=SIZE, image_quality=export.IMAGE_QUALITY)
    layout = dict(plain.unwrapped.observation_layout)
    state = export.state_index(export.state_layout(layout, ("front",)))
    inputs = Inputs(max(p.stop for p in layout.values()), state, layout["object_pos"], ("front",), "")
    _, env = vector_env("PickPlace-v2", "front")
    try:
        obs, _ = env.reset(seed=[9])
        raw, _ = plain.reset(seed=9)
        for _ in range(3):
            got = inputs.observation(preprocess_observation(obs))
            assert np.array_equal(got["front_image"][0], raw["front_image"])
            assert np.array_equal(got["desired_goal"][0], raw["desired_goal"].astype(np.float32))
            assert np.array_equal(got["observation"][0, state], raw["observation"][state].astype(np.float32))
            assert not np.delete(got["observation"][0], state).any()
            action = env.action_space.sample()
            obs, *_ = env.step(action)
            raw, *_ = plain.step(action[0])
    finally:
        env.close()
        plain.close()


def test_a_camera_run_acts_in_lerobot_as_in_our_env(tmp_path: pathlib.Path) -> None:
    """A `gym-fetch train --inputs pixels` run through `export_policy`: on LeRobot's batch from the env with
    its cameras, size and drawing quality, its actions are the run's own on our env's observation."""
    from lerobot_env_fetch.export_policy import eval_command, export_policy
    from lerobot_env_fetch.modeling_gym_fetch import GymFetchPolicy

    from fetch.learn.runtime import load

    assert main(["collect", "--env", "PickPlace-v2", "--device", "expert", "--episodes", "2", "--render", "none",
                 "--cameras", "front", "--image-size", "32", "--out", str(tmp_path / "demos")]) == 0
    assert main(["train", str(tmp_path / "demos"), "--out", str(tmp_path / "run"), "--inputs", "pixels", "--steps",
                 "5", "--batch-size", "16"]) == 0
    config = export_policy(tmp_path / "run", tmp_path / "policy")
    options = dict(a.removeprefix("--env.").split("=") for a in eval_command(tmp_path / "policy", config)
                   if a.startswith("--env.") and a != "--env.type=fetch")
    assert options == {"task": "PickPlace-v2", "cameras": "front", "image_size": "32", "image_quality": "fast"}
    wrapped, ours = GymFetchPolicy.from_pretrained(tmp_path / "policy"), load(tmp_path / "run")
    cfg = make_env_config("fetch", **{**options, "image_size": int(options["image_size"])}, terminate_on_success=False)
    env = make_env(cfg, n_envs=1, use_async_envs=False)["fetch"][0]
    _act_in_lockstep(wrapped, ours, env, gym.make(ours.env_id, **ours.env_kwargs, **ours.observation_kwargs),
                     seed=11, steps=20)
