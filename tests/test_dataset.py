"""Datasets written by the collector: robomimic's layout, exact replay, resume, locking, bad input."""

from __future__ import annotations

import json
import pathlib
import shutil
import subprocess
import sys

import gymnasium as gym
import h5py
import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset, validate
from fetch.dataset.episode import EpisodeBuffer
from fetch.dataset.schema import Layout
from robomimic_rules import assert_robomimic_loadable

ENV = "Drawer-open-v2"


def collect(out: pathlib.Path, *extra: str, env: str = ENV, episodes: int = 3) -> int:
    return main(["collect", "--env", env, "--device", "expert", "--episodes", str(episodes), "--render", "none",
                 "--out", str(out), *extra])


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("demos")
    assert collect(out, episodes=4) == 0
    return out


@pytest.fixture
def copy(dataset: pathlib.Path, tmp_path: pathlib.Path) -> pathlib.Path:
    out = tmp_path / "copy"
    shutil.copytree(dataset, out)
    return out


def test_layout_is_robomimic_s(dataset: pathlib.Path) -> None:
    with h5py.File(dataset / "demos.hdf5", "r") as f:
        data = f["data"]
        env_args = json.loads(data.attrs["env_args"])
        assert env_args["env_name"] == ENV and env_args["type"] == 2 and env_args["env_kwargs"] == {
            "reward_type": "sparse"}
        names = sorted(data.keys(), key=lambda n: int(n.split("_")[1]))
        assert names == [f"demo_{i}" for i in range(4)]
        total = 0
        seeds = set()
        for name in names:
            g = data[name]
            t = int(g.attrs["num_samples"])
            total += t
            seeds.add(int(g.attrs["seed"]))
            assert g.attrs["env_id"] == ENV and bool(g.attrs["success"])
            assert g["actions"].shape == (t, 4) and g["actions"].dtype == np.float32
            assert np.abs(g["actions"][()]).max() <= 1.0
            for key in ("observation", "achieved_goal", "desired_goal"):
                assert g[f"obs/{key}"].shape[0] == t and g[f"next_obs/{key}"].shape[0] == t
                np.testing.assert_array_equal(g[f"obs/{key}"][1:], g[f"next_obs/{key}"][:-1])
            assert g["states"].shape[0] == t + 1
            for key in ("rewards", "dones", "terminated", "truncated", "is_success", "timestamps"):
                assert g[key].shape == (t,), key
            assert g["dones"][-1] == 1 and not g["dones"][:-1].any()
            # success held for the default 10 steps, then the attempt stopped
            assert g["is_success"][-10:].all()
        assert int(data.attrs["total"]) == total
        assert len(seeds) == 4
        masks = {k: [n.decode() for n in f[f"mask/{k}"][()]] for k in ("train", "valid")}
        assert sorted(masks["train"] + masks["valid"], key=lambda n: int(n[5:])) == names
        assert data.attrs["model_hash"] == gym.make(ENV).unwrapped.model_hash()  # type: ignore[attr-defined]


def test_robomimic_loader_rules(dataset: pathlib.Path) -> None:
    assert_robomimic_loadable(dataset / "demos.hdf5")


def test_reset_with_the_seed_and_the_actions_reproduces_every_observation(dataset: pathlib.Path) -> None:
    env = gym.make(ENV, max_episode_steps=500)
    with open_dataset(dataset) as ds:
        for name in ds.demo_names:
            g = ds.demo(name)
            obs, _ = env.reset(seed=int(g.attrs["seed"]))
            for key in obs:
                np.testing.assert_array_equal(obs[key], g[f"obs/{key}"][0])
            for t, action in enumerate(g["actions"][()]):
                obs, *_ = env.step(action)
                for key in obs:
                    assert np.array_equal(obs[key], g[f"next_obs/{key}"][t]), (name, t, key)


def test_replay_check_passes_and_catches_a_changed_state(copy: pathlib.Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(copy / "demos.hdf5"), "--check"]) == 0
    assert "4 exact, 0 deviating" in capsys.readouterr().out
    with h5py.File(copy / "episodes" / "demo_2.hdf5", "r+") as f:
        f["demo_2/states"][7, 3] += 1e-9
    assert main(["replay", str(copy), "--check"]) == 1
    out = capsys.readouterr().out
    assert "demo_2" in out and "states[7, 3]" in out and "1 deviating" in out


def test_replay_says_when_the_demos_were_recorded_on_another_model(copy: pathlib.Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(copy), "--check"]) == 0
    assert "another model" not in capsys.readouterr().out
    other = "ab" * 32  # a well-formed hash of some other model (an older release's physics, another MuJoCo)
    with h5py.File(copy / "demos.hdf5", "r+") as f:  # the index holds the dataset's attributes
        f["data"].attrs["model_hash"] = other
    assert main(["replay", str(copy), "--check"]) == 0  # the same physics after all: still exact
    out = capsys.readouterr().out
    assert f"recorded on another model than this install's (model hash {other[:12]}, here " in out
    assert "4 exact, 0 deviating" in out


def test_info_validates(copy: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(copy)]) == 0
    assert "4 (4 successful)" in capsys.readouterr().out
    with h5py.File(copy / "episodes" / "demo_1.hdf5", "r+") as f:
        f["demo_1/actions"][0, 0] = 1.5
        f["demo_1"].attrs["num_samples"] = 3
    assert main(["info", str(copy)]) == 1
    out = capsys.readouterr().out
    assert "demo_1: actions has shape" in out and "data.attrs['total']" in out


def test_collect_resumes_and_numbers_on(copy: pathlib.Path) -> None:
    with open_dataset(copy) as ds:
        seeds_before = {int(ds.demo(n).attrs["seed"]) for n in ds.demo_names}
    assert collect(copy, episodes=2) == 0
    with open_dataset(copy) as ds:
        assert ds.demo_names == [f"demo_{i}" for i in range(6)]
        seeds = [int(ds.demo(n).attrs["seed"]) for n in ds.demo_names]
        assert len(set(seeds)) == 6 and seeds_before <= set(seeds)
        assert validate(ds) == []


def test_collect_refuses_a_mismatched_dataset(copy: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = (copy / "demos.hdf5").read_bytes()
    assert collect(copy, "--max-steps", "300", episodes=1) == 2
    err = capsys.readouterr().err
    assert "max_steps" in err and "300" in err and "--out" in err
    assert collect(copy, env="Drawer-close-v2", episodes=1) == 2
    assert "Drawer-close-v2" in capsys.readouterr().err
    assert (copy / "demos.hdf5").read_bytes() == before


def test_a_second_collector_on_the_same_output_refuses(tmp_path: pathlib.Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    from fetch.dataset.background import BackgroundWriter

    first = BackgroundWriter(tmp_path, on_saved=None)  # holds the directory's lock
    try:
        assert collect(tmp_path, episodes=1) == 2
        assert "in use by another collector" in capsys.readouterr().err
    finally:
        first._unlock()
    assert collect(tmp_path, episodes=1) == 0


@pytest.mark.parametrize("made", [True, False], ids=["new-out", "existing-empty-out"])
def test_a_stop_while_the_collector_starts_leaves_no_directory_that_is_not_a_dataset(
        tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch, made: bool) -> None:
    """A Ctrl-C landing between the directory's creation and its index's (CI hit it a second after
    `collect` started) left an empty `--out`, which tools then called "no such file". Now the directory
    goes with the stop if the collector made it; one that was there before stays, as it was."""
    import signal

    from fetch.dataset.writer import DatasetWriter
    from fetch.stopping import Stopped

    def stopped(self: DatasetWriter) -> None:  # the signal's handler raises here, as a Ctrl-C would
        (self.out_dir / ".demos.hdf5.half.tmp").write_bytes(b"\x89HDF")
        raise Stopped(signal.SIGINT)

    out = tmp_path / "out"
    if not made:
        out.mkdir()
    monkeypatch.setattr(DatasetWriter, "_write_index", stopped)
    assert collect(out, episodes=1) == 128 + signal.SIGINT
    assert out.exists() != made
    monkeypatch.undo()
    assert collect(out, episodes=1) == 0  # and the directory is free: the lock was let go
    with open_dataset(out) as ds:
        assert validate(ds) == [] and len(ds.demo_names) == 1


@pytest.mark.parametrize("content", [b"", b"not an hdf5 file at all" * 10, b"\x89HDF\r\n\x1a\n" + b"\0" * 100])
def test_a_corrupt_file_is_a_clear_error_naming_it(tmp_path: pathlib.Path, content: bytes,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.hdf5"
    bad.write_bytes(content)
    for command in ("info", "replay"):
        assert main([command, str(bad)]) == 2
        err = capsys.readouterr().err
        assert str(bad) in err and "not a readable HDF5 file" in err


def test_a_foreign_or_truncated_file_is_a_clear_error(copy: pathlib.Path, tmp_path: pathlib.Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    foreign = tmp_path / "robosuite.hdf5"
    with h5py.File(foreign, "w") as f:
        f.create_group("data").attrs["env_args"] = "{}"
    assert main(["info", str(foreign)]) == 2
    assert "not a gym-fetch-v2 dataset" in capsys.readouterr().err
    plain = tmp_path / "plain.hdf5"
    with h5py.File(plain, "w") as f:
        f["x"] = 1
    assert main(["replay", str(plain)]) == 2
    assert "no 'data' group" in capsys.readouterr().err
    truncated = tmp_path / "truncated.hdf5"
    truncated.write_bytes((copy / "demos.hdf5").read_bytes()[:3000])
    assert main(["info", str(truncated)]) == 2
    assert str(truncated) in capsys.readouterr().err
    (copy / "episodes" / "demo_3.hdf5").unlink()
    assert main(["info", str(copy)]) == 1
    assert "demo_3" in capsys.readouterr().out
    assert main(["info", str(tmp_path / "missing.hdf5")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_npz_format_keeps_the_seed_s_keys(tmp_path: pathlib.Path) -> None:
    assert collect(tmp_path, "--format", "npz", env="Reach-v2", episodes=2) == 0
    files = sorted(tmp_path.glob("Reach-v2_ep*.npz"))
    assert [f.name[:15] for f in files] == ["Reach-v2_ep0000", "Reach-v2_ep0001"]
    with np.load(files[0]) as z:
        assert {"metadata_json", "info_json", "action", "reward", "terminated", "truncated",
                "obs__observation", "obs__achieved_goal", "obs__desired_goal"} <= set(z.files)
        t = len(z["action"])
        assert z["obs__observation"].shape[0] == t + 1 and z["states"].shape[0] == t + 1
        meta = json.loads(str(z["metadata_json"]))
        assert meta["env_id"] == "Reach-v2" and meta["successful"] is True and "seed" in meta
    # resuming continues the numbering
    assert collect(tmp_path, "--format", "npz", env="Reach-v2", episodes=1) == 0
    assert sorted(f.name[:15] for f in tmp_path.glob("*.npz"))[-1] == "Reach-v2_ep0002"


def _script(path: pathlib.Path, events: object) -> str:
    path.write_text(json.dumps(events))
    return str(path)


def test_scripted_events_discard_keep_failures_and_max_steps(tmp_path: pathlib.Path) -> None:
    idle = {"action": [0, 0, 0, 0]}
    # attempt 0: 5 idle steps then Y (discarded); attempt 1: 80 idle steps (fails at --max-steps)
    events = [idle] * 5 + [{"action": [0, 0, 0, 0], "reset": True}] + [idle] * 80 + [{"quit": True}]
    script = _script(tmp_path / "events.json", events)
    out = tmp_path / "out"
    code = main(["collect", "--env", "Push-v2", "--device", "scripted", "--scripted-json", script, "--render",
                 "none", "--max-steps", "80", "--keep-failures", "--out", str(out)])
    assert code == 0
    with open_dataset(out) as ds:
        assert ds.demo_names == ["demo_0"]
        g = ds.demo("demo_0")
        assert int(g.attrs["num_samples"]) == 80 and not g.attrs["success"] and int(g.attrs["attempt"]) == 1
        assert g["truncated"][-1] and not g["truncated"][:-1].any()
        assert ds.masks()["failed"] == ["demo_0"] and ds.masks()["train"] == []
        assert validate(ds) == []


@pytest.mark.parametrize("content, problem", [
    ("{", "not valid JSON"), ('{"action": [0, 0, 0, 0]}', "JSON list"),
    ('[{"action": [0, 0]}]', "event 0: \"action\" must be 4 finite numbers"),
    ('[{"acton": [0, 0, 0, 0]}]', "unknown keys"),
])
def test_a_malformed_script_names_the_file_and_the_problem(tmp_path: pathlib.Path, content: str, problem: str,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "events.json"
    path.write_text(content)
    code = main(["collect", "--env", "Reach-v2", "--device", "scripted", "--scripted-json", str(path),
                 "--render", "none", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and str(path) in err and problem in err


def test_bad_arguments_name_the_valid_choices(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert collect(tmp_path, env="Bin-pik-v2") == 2
    err = capsys.readouterr().err
    assert "Bin-pik-v2" in err and "Bin-pick-v2" in err
    assert collect(tmp_path, "--max-steps", "0") == 2
    assert "--max-steps must be at least 1" in capsys.readouterr().err


def test_no_stop_on_success_runs_to_max_steps_and_is_saved(tmp_path: pathlib.Path) -> None:
    assert collect(tmp_path, "--no-stop-on-success", "--max-steps", "60", env="Reach-v2", episodes=1) == 0
    with open_dataset(tmp_path) as ds:
        g = ds.demo("demo_0")
        assert int(g.attrs["num_samples"]) == 60 and bool(g.attrs["success"])


def test_episode_buffer_grows_past_its_capacity() -> None:
    layout = Layout(obs_sizes=(("observation", 2),), state_size=3)
    buf = EpisodeBuffer(layout, capacity=2)
    buf.begin({"observation": np.array([0.0, 0.0])}, np.zeros(3))
    for t in range(5):
        buf.state_row()[:] = t + 1
        buf.record(np.full(4, 0.1 * t, np.float32), {"observation": np.array([t + 1.0, 0.0])}, -1.0, False,
                   False, False, float(t))
    demo = buf.demo({"seed": 0, "success": False})
    assert demo.num_samples == 5
    np.testing.assert_array_equal(demo.arrays["states"][:, 0], [0, 1, 2, 3, 4, 5])
    np.testing.assert_array_equal(demo.arrays["obs/observation"][:, 0], [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(demo.arrays["next_obs/observation"][:, 0], [1, 2, 3, 4, 5])
    np.testing.assert_allclose(demo.arrays["actions"][:, 0], [0, 0.1, 0.2, 0.3, 0.4], rtol=1e-6)


def test_python_m_entry_points(tmp_path: pathlib.Path) -> None:
    for module in ("fetch.cli", "fetch.collect"):
        args = ["collect"] if module == "fetch.cli" else []
        run = subprocess.run([sys.executable, "-m", module, *args, "--env", "Reach-v2", "--device", "expert",
                              "--episodes", "1", "--render", "none", "--out", str(tmp_path / module)],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        assert "saved demo_0" in run.stdout
    for module in ("fetch.cli", "fetch.collect"):
        with open_dataset(tmp_path / module) as ds:
            assert ds.env_id == "Reach-v2" and len(ds.demo_names) == 1


def test_cameras_are_recorded_as_rendered_from_the_saved_states(tmp_path: pathlib.Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    from fetch.rendering import OffscreenRenderer

    assert collect(tmp_path, "--cameras", "front,wrist", "--image-size", "32", env="Reach-v2", episodes=1) == 0
    env = gym.make("Reach-v2").unwrapped
    renderer = OffscreenRenderer(env.model, 32, 32, "fast")  # type: ignore[attr-defined]
    with open_dataset(tmp_path) as ds:
        assert validate(ds) == [] and ds.layout.cameras == ("front", "wrist") and ds.layout.image_quality == "fast"
        g = ds.demo("demo_0")
        states = g["states"][()]
        for camera in ("front", "wrist"):
            frames, after = g[f"obs/{camera}_image"][()], g[f"next_obs/{camera}_image"][()]
            assert frames.shape == (len(states) - 1, 32, 32, 3) and frames.dtype == np.uint8
            np.testing.assert_array_equal(frames[1:], after[:-1])
            for t in (0, len(states) - 1):
                env.set_state(states[t])  # type: ignore[attr-defined]
                recorded = frames[t] if t < len(frames) else after[-1]
                np.testing.assert_array_equal(renderer.render(env.data, camera), recorded)  # type: ignore[attr-defined]
    renderer.close()
    # --image-quality full records the scene as the viewer draws it, and says so in the layout
    assert collect(tmp_path / "full", "--cameras", "front", "--image-size", "32", "--image-quality", "full",
                   env="Reach-v2", episodes=1) == 0
    renderer = OffscreenRenderer(env.model, 32, 32, "full")  # type: ignore[attr-defined]
    with open_dataset(tmp_path / "full") as ds:
        assert ds.layout.image_quality == "full"
        g = ds.demo("demo_0")
        env.set_state(g["states"][0])  # type: ignore[attr-defined]
        np.testing.assert_array_equal(renderer.render(env.data, "front"), g["obs/front_image"][0])  # type: ignore[attr-defined]
    renderer.close()
    assert collect(tmp_path / "other", "--cameras", "fron", env="Reach-v2", episodes=1) == 2
    assert "unknown camera 'fron'" in capsys.readouterr().err


def test_extra_filter_keys_are_allowed_but_each_demo_needs_one_split(copy: pathlib.Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    with h5py.File(copy / "demos.hdf5", "r+") as f:
        f["mask/hard"] = np.array([b"demo_0", b"demo_1"])  # robomimic-style extra filter key: fine
    assert main(["info", str(copy)]) == 0
    with h5py.File(copy / "demos.hdf5", "r+") as f:
        del f["mask/train"]
        f["mask/train"] = np.array([b"demo_1", b"demo_2", b"demo_3"])  # demo_0 now only in "hard"
    assert main(["info", str(copy)]) == 1
    assert "demo_0 is in no mask (train, valid or failed)" in capsys.readouterr().out
