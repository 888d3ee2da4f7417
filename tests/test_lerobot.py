"""`gym-fetch export --to lerobot`: the LeRobotDataset v3.0 files, read back with pyarrow and PyAV (no lerobot;
tests/test_lerobot_consumer.py loads them with lerobot itself), exact values, atomic writing, bad input."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
pytest.importorskip("av")

import fetch  # noqa: E402
from fetch.cli import main  # noqa: E402
from fetch.dataset import open_dataset  # noqa: E402
from fetch.dataset.exports import lerobot  # noqa: E402
from fetch.dataset.render.frames import StateRenderer  # noqa: E402
from fetch.dataset.render.video import read_video  # noqa: E402

SIZE = 64


def export(src: pathlib.Path, out: pathlib.Path, *extra: str) -> int:
    return main(["export", str(src), "--to", "lerobot", "--repo-id", "test/fetch", "--out", str(out), *extra])


@pytest.fixture(scope="module")
def exported(reach_demos: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("lerobot") / "ds"
    assert export(reach_demos, out, "--cameras", "front,wrist", "--image-size", str(SIZE)) == 0
    return out


def demo_arrays(src: pathlib.Path) -> list[dict[str, np.ndarray]]:
    with open_dataset(src) as ds:
        return [ds.arrays(name) for name in ds.demo_names]


def test_every_env_has_a_task_string() -> None:
    from fetch.tasks import task_class

    strings = [task_class(env_id).instruction for env_id in fetch.ENV_IDS]
    assert all(isinstance(s, str) and s for s in strings) and len(set(strings)) == len(strings)


def test_info_and_layout(exported: pathlib.Path, reach_demos: pathlib.Path) -> None:
    info = json.loads((exported / "meta/info.json").read_text())
    demos = demo_arrays(reach_demos)
    frames = sum(len(d["actions"]) for d in demos)
    assert info["codebase_version"] == "v3.0"
    counts = (info["total_episodes"], info["total_frames"], info["total_tasks"], info["fps"])
    assert counts == (len(demos), frames, 1, 25)
    assert info["splits"] == {"train": f"0:{len(demos)}"}
    features = info["features"]
    assert list(features)[-5:] == ["timestamp", "frame_index", "episode_index", "index", "task_index"]
    assert features["observation.state"]["shape"] == [demos[0]["obs/observation"].shape[1]]
    assert features["observation.state"]["names"][:3] == ["grip_pos_x", "grip_pos_y", "grip_pos_z"]
    assert features["action"] == {"dtype": "float32", "shape": [4], "names": ["x", "y", "z", "gripper"]}
    for camera in ("front", "wrist"):
        video = features[f"observation.images.{camera}"]
        assert video["dtype"] == "video" and video["shape"] == [SIZE, SIZE, 3]
        assert video["info"]["video.codec"] == "h264" and video["info"]["video.fps"] == 25
        assert (exported / info["video_path"].format(video_key=f"observation.images.{camera}", chunk_index=0,
                                                     file_index=0)).is_file()
    assert (exported / info["data_path"].format(chunk_index=0, file_index=0)).is_file()
    tasks = pq.read_table(exported / "meta/tasks.parquet")
    assert tasks.column("__index_level_0__").to_pylist() == ["move the gripper to the goal"]
    assert b"pandas" in tasks.schema.metadata  # how pandas (LeRobot's reader) finds the task strings as the index
    assert not list(exported.parent.glob(".*"))  # nothing left beside it


def test_frames_are_the_demos_exactly(exported: pathlib.Path, reach_demos: pathlib.Path) -> None:
    demos = demo_arrays(reach_demos)
    table = pq.read_table(exported / "data/chunk-000/file-000.parquet")

    def column(key: str) -> np.ndarray:
        return np.asarray(table.column(key).to_pylist())

    want_state = np.concatenate([d["obs/observation"] for d in demos]).astype(np.float32)
    assert np.array_equal(column("observation.state").astype(np.float32), want_state)
    goals = np.concatenate([d["obs/desired_goal"] for d in demos]).astype(np.float32)
    assert np.array_equal(column("observation.environment_state").astype(np.float32), goals)
    # DART demos: `action` is what a policy imitates, the expert's clean action; the one applied beside it.
    assert all("expert_actions" in d for d in demos)
    assert np.array_equal(column("action").astype(np.float32), np.concatenate([d["expert_actions"] for d in demos]))
    assert np.array_equal(column("executed_action").astype(np.float32), np.concatenate([d["actions"] for d in demos]))
    assert not np.array_equal(column("action"), column("executed_action"))
    assert np.array_equal(column("next.reward"), np.concatenate([d["rewards"] for d in demos]))
    assert np.array_equal(column("next.done"), np.concatenate([d["dones"] for d in demos]).astype(bool))
    assert np.array_equal(column("next.success"), np.concatenate([d["is_success"] for d in demos]).astype(bool))
    lengths = [len(d["actions"]) for d in demos]
    assert np.array_equal(column("frame_index"), np.concatenate([np.arange(n) for n in lengths]))
    assert np.array_equal(column("episode_index"), np.repeat(np.arange(len(demos)), lengths))
    assert np.array_equal(column("index"), np.arange(sum(lengths)))
    assert np.array_equal(column("timestamp").astype(np.float32),
                          np.concatenate([np.arange(n) / 25 for n in lengths]).astype(np.float32))
    assert set(column("task_index")) == {0}


def test_episodes_say_where_their_rows_and_frames_are(exported: pathlib.Path, reach_demos: pathlib.Path) -> None:
    lengths = [len(d["actions"]) for d in demo_arrays(reach_demos)]
    rows = pq.read_table(exported / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    starts = np.concatenate([[0], np.cumsum(lengths)])
    assert [r["episode_index"] for r in rows] == list(range(len(lengths)))
    assert [r["length"] for r in rows] == lengths
    assert [r["dataset_from_index"] for r in rows] == list(starts[:-1])
    assert [r["dataset_to_index"] for r in rows] == list(starts[1:])
    for camera in ("front", "wrist"):
        key = f"videos/observation.images.{camera}"
        assert [r[f"{key}/from_timestamp"] for r in rows] == pytest.approx(starts[:-1] / 25)
        assert [r[f"{key}/to_timestamp"] for r in rows] == pytest.approx(starts[1:] / 25)
    assert all(r["tasks"] == ["move the gripper to the goal"] for r in rows)
    assert [r["gym_fetch/demo"] for r in rows] == ["demo_0", "demo_1"]


def test_stats_are_those_of_the_frames(exported: pathlib.Path, reach_demos: pathlib.Path) -> None:
    demos = demo_arrays(reach_demos)
    stats = json.loads((exported / "meta/stats.json").read_text())
    actions = np.concatenate([d["expert_actions"] for d in demos]).astype(np.float64)
    assert np.allclose(stats["action"]["mean"], actions.mean(0), rtol=0, atol=1e-12)
    assert np.allclose(stats["action"]["std"], actions.std(0), rtol=0, atol=1e-12)
    assert np.allclose(stats["action"]["q50"], np.quantile(actions, 0.5, axis=0), rtol=0, atol=1e-12)
    assert stats["action"]["count"] == [len(actions)]
    image = stats["observation.images.front"]
    assert np.shape(image["mean"]) == (3, 1, 1) and 0 < np.min(image["mean"]) < np.max(image["max"]) <= 1
    assert set(stats) >= {"observation.state", "executed_action", "next.reward", "timestamp", "index"}


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 10 * np.log10(255**2 / max(mse, 1e-12))


def test_videos_are_fresh_renders_within_codec_tolerance(exported: pathlib.Path, reach_demos: pathlib.Path) -> None:
    with open_dataset(reach_demos) as ds:
        states = np.concatenate([ds.demo(n)["states"][:-1] for n in ds.demo_names])
        env_id, env_kwargs = ds.env_id, ds.env_kwargs
    with StateRenderer(env_id, env_kwargs, SIZE, SIZE) as renderer:
        for camera in ("front", "wrist"):
            frames, rate = read_video(exported / f"videos/observation.images.{camera}/chunk-000/file-000.mp4")
            assert rate == 25 and len(frames) == len(states)
            fresh = np.stack([renderer.frame(s, camera) for s in states])
            scores = [psnr(f, g) for f, g in zip(frames, fresh, strict=True)]
            assert min(scores) > 30, (camera, min(scores))
            # the same frames one step out of line score worse: the check sees misalignment
            assert np.mean([psnr(f, g) for f, g in zip(frames[1:], fresh[:-1], strict=True)]) < np.mean(scores)


def test_image_quality_draws_the_videos_so_and_the_card_gives_the_env_that_matches(
        reach_demos: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """`--image-quality fast`: the videos are the fast drawing of the states (nearer it than the full one, which
    the default draws), so a LeRobot policy can learn from the images a camera policy learnt from; the dataset
    card gives the lerobot-eval env flags that draw them so."""
    out = tmp_path / "ds"
    assert export(reach_demos, out, "--cameras", "front", "--image-size", str(SIZE), "--image-quality", "fast") == 0
    with open_dataset(reach_demos) as ds:
        states = np.concatenate([ds.demo(n)["states"][:-1] for n in ds.demo_names])
        env_id, env_kwargs = ds.env_id, ds.env_kwargs
    frames, _ = read_video(out / "videos/observation.images.front/chunk-000/file-000.mp4")
    scores = {}
    for quality in ("fast", "full"):
        with StateRenderer(env_id, env_kwargs, SIZE, SIZE, quality) as renderer:
            fresh = [renderer.frame(s, "front") for s in states]
        scores[quality] = np.mean([psnr(f, g) for f, g in zip(frames, fresh, strict=True)])
    assert scores["fast"] > 30 and scores["fast"] > scores["full"] + 3, scores
    card = (out / "README.md").read_text()
    assert (f"lerobot-eval --env.type=fetch --env.task={env_id} --env.cameras=front --env.image_size={SIZE} "
            "--env.image_quality=fast`") in card, card


@pytest.fixture(scope="module")
def reach_with_images(reach_demos: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """The Reach demos with their front camera's images recorded (64 px, fast), as `collect --cameras` keeps them."""
    copy = tmp_path_factory.mktemp("images") / "demos"
    shutil.copytree(reach_demos, copy)
    assert main(["render-obs", str(copy), "--camera", "front", "--size", str(SIZE), "--quality", "fast"]) == 0
    return copy


def _export_without_gl(src: pathlib.Path, out: pathlib.Path, *extra: str) -> subprocess.CompletedProcess[str]:
    """The export in a process where MuJoCo cannot render (`MUJOCO_GL=disable`)."""
    argv = [sys.executable, "-m", "fetch.cli", "export", str(src), "--to", "lerobot", "--repo-id", "test/fetch",
            "--out", str(out), *extra]
    return subprocess.run(argv, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "MUJOCO_GL": "disable"})


def test_recorded_images_are_the_videos_and_need_no_renderer(reach_with_images: pathlib.Path,
                                                              tmp_path: pathlib.Path) -> None:
    """Recorded at the size and quality asked for, a dataset's own images are the videos: read, not drawn again
    (the export runs where nothing can render, and says where its frames came from); asked for another size,
    the export draws them, which that process cannot."""
    out = tmp_path / "ds"
    done = _export_without_gl(reach_with_images, out, "--cameras", "front", "--image-quality", "fast")
    assert done.returncode == 0, done.stderr
    assert f"videos of the dataset's own {SIZE} px fast images" in done.stdout, done.stdout
    assert "drawn at image quality `fast`: the dataset's own images." in (out / "README.md").read_text()
    with open_dataset(reach_with_images) as ds:
        stored = np.concatenate([ds.demo(n)["obs/front_image"][()] for n in ds.demo_names])
    frames, _ = read_video(out / "videos/observation.images.front/chunk-000/file-000.mp4")
    assert len(frames) == len(stored)
    scores = [psnr(f, g) for f, g in zip(frames, stored, strict=True)]
    assert min(scores) > 30, min(scores)
    assert np.mean([psnr(f, g) for f, g in zip(frames[1:], stored[:-1], strict=True)]) < np.mean(scores)
    other = _export_without_gl(reach_with_images, tmp_path / "other", "--cameras", "front", "--image-size", "32",
                               "--image-quality", "fast")
    assert other.returncode != 0 and not (tmp_path / "other").exists(), other.stdout


def test_images_recorded_otherwise_are_drawn_from_the_states(reach_with_images: pathlib.Path,
                                                             tmp_path: pathlib.Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """At another quality (the default `full`), or for a camera the dataset did not record, the videos are
    drawn from the saved states, and the line says so."""
    for extra in (["--cameras", "front"], ["--cameras", "front,wrist", "--image-quality", "fast"]):
        out = tmp_path / "-".join(extra).replace(",", "_")
        assert export(reach_with_images, out, *extra) == 0
        quality = extra[-1] if "--image-quality" in extra else "full"
        assert f"videos of {SIZE} px {quality} images drawn from the saved states" in capsys.readouterr().out


def test_no_cameras_writes_no_video(reach_demos: pathlib.Path, tmp_path: pathlib.Path) -> None:
    assert export(reach_demos, tmp_path / "ds", "--cameras", "none") == 0
    info = json.loads((tmp_path / "ds/meta/info.json").read_text())
    assert info["video_path"] is None and not (tmp_path / "ds/videos").exists()
    assert not any(f["dtype"] == "video" for f in info["features"].values())


@pytest.mark.parametrize(("args", "message"), [
    (["--repo-id", "no-namespace"], "bad --repo-id 'no-namespace'"),
    (["--fps", "30"], "--fps 30: a frame is one control step of 0.04 s"),
    (["--cameras", "front,ceiling"], "unknown camera 'ceiling'; known: "),
    (["--cameras", "front,front"], "--cameras names front more than once"),
    (["--image-size", "63"], "--image-size must be an even number"),
    (["--image-quality", "nice"], "--image-quality 'nice': choose one of fast, full"),
    (["--dataset-id", "x/y-v0"], "--dataset-id is for --to minari"),
    (["--demos", "nonesuch"], "unknown demo selection 'nonesuch'"),
])
def test_bad_input_is_one_line_before_any_work(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                               capsys: pytest.CaptureFixture[str], args: list[str],
                                               message: str) -> None:
    argv = ["export", str(reach_demos), "--to", "lerobot", "--out", str(tmp_path / "ds")]
    argv += args if "--repo-id" in args else ["--repo-id", "test/fetch", *args]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not list(tmp_path.iterdir())


def test_missing_repo_id_and_lerobot_flags_elsewhere(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(reach_demos), "--to", "lerobot", "--out", str(tmp_path / "ds")]) == 2
    assert "--to lerobot needs --repo-id NAME" in capsys.readouterr().err
    assert main(["export", str(reach_demos), "--to", "npz", "--out", str(tmp_path / "n"), "--fps", "25"]) == 2
    assert "--fps is for --to lerobot" in capsys.readouterr().err
    assert main(["export", str(reach_demos), "--to", "npz", "--out", str(tmp_path / "n"),
                 "--image-quality", "fast"]) == 2
    assert "--image-quality is for --to lerobot" in capsys.readouterr().err


def test_an_existing_dataset_is_kept_unless_force(exported: pathlib.Path, reach_demos: pathlib.Path,
                                                  tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "ds"
    shutil.copytree(exported, target)
    assert export(reach_demos, target, "--cameras", "none") == 2
    assert "already exists and is not empty" in capsys.readouterr().err
    assert (target / "videos").is_dir()
    assert export(reach_demos, target, "--cameras", "none", "--force") == 0
    assert not (target / "videos").exists()  # replaced whole, not merged
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def _start_export(src: pathlib.Path, target: pathlib.Path, *extra: str) -> subprocess.Popen[bytes]:
    """An export in another process; with a camera it runs for seconds after its partial directory
    appears (the render workers start), so a signal sent then lands while it works."""
    argv = [sys.executable, "-m", "fetch.cli", "export", str(src), "--to", "lerobot", "--repo-id", "test/fetch",
            "--out", str(target), "--image-size", str(SIZE), *extra]
    return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _wait_for(path: pathlib.Path, proc: subprocess.Popen[bytes], timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        stderr = proc.stderr.read() if proc.poll() is not None and proc.stderr else b""
        assert proc.poll() is None, f"the export ended before {path} appeared: {stderr.decode()}"
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.01)


def test_a_killed_export_leaves_nothing_or_the_old_dataset(exported: pathlib.Path, reach_demos: pathlib.Path,
                                                           tmp_path: pathlib.Path) -> None:
    target = tmp_path / "ds"
    partial = tmp_path / ".ds.partial"

    def files() -> dict[pathlib.Path, bytes]:
        return {p.relative_to(target): p.read_bytes() for p in target.rglob("*") if p.is_file()}

    # SIGKILL while it works: no target at all (its hidden partial directory stays, for the next run to remove)
    proc = _start_export(reach_demos, target)
    _wait_for(partial, proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not target.exists() and partial.is_dir()
    shutil.rmtree(partial)  # so that the next waits see their own
    # Ctrl-C over an existing dataset with --force: the old one is still there, whole, and nothing else
    shutil.copytree(exported, target)
    before = files()
    proc = _start_export(reach_demos, target, "--force", "--cameras", "front")
    _wait_for(partial, proc)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=120) == 130, proc.stderr.read().decode() if proc.stderr else ""
    assert files() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
    # SIGKILL over it: the same
    proc = _start_export(reach_demos, target, "--force", "--cameras", "front")
    _wait_for(partial, proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert files() == before
    # the next run completes and removes what the killed one left
    assert export(reach_demos, target, "--force", "--cameras", "none") == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
    assert json.loads((target / "meta/info.json").read_text())["video_path"] is None


def test_image_stats_from_pixel_counts_are_numpys() -> None:
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (7, 9, 11, 3), dtype=np.uint8)
    frames[..., 2] = rng.integers(30, 40, (7, 9, 11))  # a narrow channel: quantiles between few values
    got = lerobot.image_stats(lerobot.pixel_counts(frames), len(frames))
    pixels = frames.reshape(-1, 3).astype(np.float64) / 255
    want = {"min": pixels.min(0), "max": pixels.max(0), "mean": pixels.mean(0), "std": pixels.std(0)}
    want |= {f"q{round(q * 100):02d}": np.quantile(pixels, q, axis=0) for q in lerobot.QUANTILES}
    for key, value in want.items():
        assert np.allclose(np.reshape(got[key], 3), value, rtol=0, atol=1e-12), key
    assert got["count"] == [7] and np.shape(got["mean"]) == (3, 1, 1)


def test_an_invalid_dataset_is_refused(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    import h5py

    copy = tmp_path / "demos"
    shutil.copytree(reach_demos, copy)
    with open_dataset(copy) as ds:
        path, group = ds.demo_file("demo_1")
    with h5py.File(path, "r+") as f:
        f[group]["actions"][0, 0] = np.nan
    assert export(copy, tmp_path / "ds") == 2
    err = capsys.readouterr().err
    assert "demo_1: actions hold NaN" in err and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demos"]


@pytest.mark.parametrize("env_id", list(fetch.ENV_IDS))
def test_a_camera_export_s_state_is_the_robot_s_own_readings(env_id: str) -> None:
    """With cameras, `observation.state` holds the robot's readings alone (no object pose: a policy that sees
    is not handed the answer), the same 10 values on every task; without, the whole observation vector."""
    import gymnasium as gym

    from fetch.dataset.exports.lerobot import ROBOT_PARTS, features, state_index, state_layout

    env = gym.make(env_id)
    layout = dict(env.unwrapped.observation_layout)  # type: ignore[attr-defined]
    width = env.observation_space["observation"].shape[0]  # type: ignore[index]
    env.close()
    seeing = features(layout, ["front"], 32, {})["observation.state"]
    blind = features(layout, [], 32, {})["observation.state"]
    assert seeing["shape"] == [10] and list(state_layout(layout, ["front"])) == list(ROBOT_PARTS)
    assert seeing["names"][:3] == ["grip_pos_x", "grip_pos_y", "grip_pos_z"]
    assert not any(n.startswith(("object", "block", "lid", "drawer", "bin")) for n in seeing["names"]), seeing
    assert blind["shape"] == [width] and len(state_index(state_layout(layout, []))) == width
