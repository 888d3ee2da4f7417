"""Our tasks as a LeRobot environment (plugins/lerobot_env_fetch, `--env.type=fetch`), checked with lerobot itself.

Runs where lerobot >= 0.6 and the plugin are installed (Python 3.12; docs/lerobot_env.md), skipped elsewhere:
every id through lerobot's own `make_env` and `preprocess_observation`; the env's keys, shapes and first
values equal those `gym-fetch export --to lerobot` writes, for a state and a camera policy; and the real
`lerobot-train` / `lerobot-eval` console scripts train on an export and evaluate it in the env.
"""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys

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
from fetch.cli import main  # noqa: E402
from fetch.dataset import lerobot as export  # noqa: E402

SIZE = 64
CAMERAS = {"state": "none", "camera": "front,wrist"}
"""The two kinds of policy: `--env.cameras` (and the export's `--cameras`) of each."""
BIN = pathlib.Path(sys.executable).parent


def vector_env(task: str, cameras: str, **kwargs: object):  # noqa: ANN201 (a gymnasium VectorEnv)
    cfg = make_env_config("fetch", task=task, cameras=cameras, image_size=SIZE, **kwargs)
    return cfg, make_env(cfg, n_envs=1, use_async_envs=False)["fetch"][0]


def test_lerobot_finds_the_plugin() -> None:
    from lerobot.envs.configs import EnvConfig

    register_third_party_plugins()  # what lerobot-train, lerobot-eval and lerobot-record call
    assert "fetch" in EnvConfig.get_known_choices()


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
    import gymnasium as gym

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
    out = tmp_path_factory.mktemp("pick") / "demos"
    assert main(["collect", "--env", "PickPlace-v2", "--device", "expert", "--episodes", "2", "--render", "none",
                 "--out", str(out)]) == 0
    return out


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
