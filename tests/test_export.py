"""`gym-fetch export`: a Minari dataset that minari opens and that re-creates the env, and the seed's npz files."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import shlex
import shutil
import subprocess
import sys

import gymnasium as gym
import minari
import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.dataset.exports.export import export_minari, export_npz
from fetch.errors import DatasetError, FetchError

ENV = "Drawer-open-v2"
MAX_STEPS = "60"


def collect(out: pathlib.Path, *extra: str, device: str = "expert", episodes: int = 3) -> int:
    return main(["collect", "--env", ENV, "--device", device, "--episodes", str(episodes), "--render", "none",
                 "--max-steps", MAX_STEPS, "--out", str(out), *extra])


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Three expert demos, then a scripted attempt that idles until --max-steps and is kept as a failure."""
    out = tmp_path_factory.mktemp("demos")
    assert collect(out) == 0
    script = out.parent / "idle.json"
    script.write_text(json.dumps([{"action": [0, 0, 0, 0]}] * int(MAX_STEPS) + [{"quit": True}]))
    assert collect(out, "--scripted-json", str(script), "--keep-failures", device="scripted", episodes=1) == 0
    with open_dataset(out) as ds:
        assert len(ds.demo_names) == 4 and ds.masks()["failed"] == ["demo_3"]
    return out


@pytest.fixture
def minari_root(tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> pathlib.Path:
    root = tmp_path / "minari"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def recorded(dataset: pathlib.Path) -> dict[str, tuple[dict[str, np.ndarray], dict[str, object]]]:
    with open_dataset(dataset) as ds:
        return {n: (ds.arrays(n), ds.attrs(n)) for n in ds.demo_names}


def test_minari_dataset_holds_the_demos_bit_for_bit(dataset: pathlib.Path, minari_root: pathlib.Path) -> None:
    done = export_minari(dataset, "fetch/drawer-open/expert-v0")
    assert done.path == minari_root / "fetch" / "drawer-open" / "expert-v0"  # MINARI_DATASETS_PATH honoured
    assert done.demos == ("demo_0", "demo_1", "demo_2")  # the failed demo_3 is left out by default
    loaded = minari.load_dataset("fetch/drawer-open/expert-v0")
    assert "fetch/drawer-open/expert-v0" in minari.list_local_datasets()
    demos = recorded(dataset)
    assert loaded.total_episodes == 3
    assert loaded.total_steps == done.steps == sum(len(demos[n][0]["actions"]) for n in done.demos)
    meta = list(loaded.storage.get_episode_metadata(range(3)))
    for episode, m, name in zip(loaded.iterate_episodes(), meta, done.demos, strict=True):
        a, attrs = demos[name]
        t = len(a["actions"])
        assert m["seed"] == attrs["seed"] and m["demo"] == name and bool(m["success"])
        for key in ("observation", "achieved_goal", "desired_goal"):
            obs = episode.observations[key]
            assert obs.shape[0] == t + 1 and obs.dtype == a[f"obs/{key}"].dtype
            np.testing.assert_array_equal(obs[:t], a[f"obs/{key}"])
            np.testing.assert_array_equal(obs[1:], a[f"next_obs/{key}"])
        assert episode.actions.dtype == np.float32
        np.testing.assert_array_equal(episode.actions, a["actions"])
        np.testing.assert_array_equal(episode.rewards, a["rewards"])
        np.testing.assert_array_equal(episode.terminations, a["terminated"])
        # the collector stopped each demo once success held: the last step is a truncation, as Minari marks it
        np.testing.assert_array_equal(episode.truncations[:-1], a["truncated"][:-1])
        assert episode.truncations[-1] and not episode.terminations[-1]
        success = episode.infos["is_success"]
        assert success.shape == (t + 1,) and success[0] == 0.0  # the reset's, then each step's
        np.testing.assert_array_equal(success[1:], a["is_success"])
        # DART demos: each step's info says what the expert meant, the clean action to learn.
        expert = episode.infos["expert_action"]
        assert expert.shape == (t + 1, 4) and np.isnan(expert[0]).all()
        np.testing.assert_array_equal(expert[1:], a["expert_actions"])
        assert not np.array_equal(expert[1:], a["actions"])
    assert loaded.storage.metadata["algorithm_name"] == "expert"
    assert loaded.storage.metadata["jpeg_encoding"] is False


def test_recovered_env_reproduces_the_demos(dataset: pathlib.Path, minari_root: pathlib.Path) -> None:
    export_minari(dataset, "fetch/drawer-open/expert-v0")
    loaded = minari.load_dataset("fetch/drawer-open/expert-v0")
    env = loaded.recover_environment()
    assert env.spec is not None and env.spec.id == ENV and env.spec.max_episode_steps == int(MAX_STEPS)
    assert env.spec.kwargs["reward_type"] == "sparse"
    seeds = [m["seed"] for m in loaded.storage.get_episode_metadata(range(loaded.total_episodes))]
    for episode, seed in zip(loaded.iterate_episodes(), seeds, strict=True):
        obs, _ = env.reset(seed=seed)
        for key, rows in episode.observations.items():
            np.testing.assert_array_equal(obs[key], rows[0])
        for t, action in enumerate(episode.actions):
            obs, reward, terminated, truncated, info = env.step(action)
            assert reward == episode.rewards[t] and info["is_success"] == episode.infos["is_success"][t + 1]
            for key, rows in episode.observations.items():
                np.testing.assert_array_equal(obs[key], rows[t + 1])
    env.close()


def test_the_metadata_asks_for_nothing_pip_cannot_install(dataset: pathlib.Path, minari_root: pathlib.Path) -> None:
    """gym-fetch-v2 is not on PyPI: a requirement on it could never be met (Minari lists it to install);
    the description says where it comes from instead."""
    export_minari(dataset, "fetch/drawer-open/expert-v0", force=True)
    metadata = minari.load_dataset("fetch/drawer-open/expert-v0").storage.metadata
    assert not any("gym-fetch" in r for r in metadata.get("requirements") or [])
    assert "installs from its source tree" in metadata["description"]


def test_the_eval_env_has_the_registered_horizon(dataset: pathlib.Path, minari_root: pathlib.Path) -> None:
    """Evaluation runs the task as registered; the collection env keeps the collector's --max-steps."""
    export_minari(dataset, "fetch/drawer-open/expert-v0", demos="all")
    loaded = minari.load_dataset("fetch/drawer-open/expert-v0")
    horizon = gym.spec(ENV).max_episode_steps
    assert horizon is not None and horizon != int(MAX_STEPS)  # else this test could not fail
    evaluation, collection = loaded.recover_environment(eval_env=True), loaded.recover_environment()
    assert evaluation.spec is not None and collection.spec is not None
    assert evaluation.spec.max_episode_steps == horizon and collection.spec.max_episode_steps == int(MAX_STEPS)
    assert evaluation.spec == dataclasses.replace(collection.spec, max_episode_steps=horizon)  # same task otherwise
    failed = loaded[3]  # the idle attempt ran to --max-steps; evaluation cuts it at the registered horizon
    evaluation.reset(seed=next(loaded.storage.get_episode_metadata([3]))["seed"])
    truncated = [evaluation.step(action)[3] for action in failed.actions[:horizon]]
    assert truncated == [False] * (horizon - 1) + [True]
    evaluation.close()
    collection.close()


def test_a_subset_export_has_its_own_default_id(dataset: pathlib.Path, minari_root: pathlib.Path,
                                                 tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    from fetch.dataset.edit import split

    src = tmp_path / "demos"
    shutil.copytree(dataset, src)
    assert split(src, 0.3)["valid"] == 1
    with open_dataset(src) as ds:
        valid = ds.masks()["valid"]
    assert main(["export", str(src), "--to", "minari"]) == 0
    assert main(["export", str(src), "--to", "minari", "--demos", "valid"]) == 0
    assert main(["export", str(src), "--to", "minari", "--demos", "all"]) == 0
    out = capsys.readouterr().out
    for dataset_id, demos in (("fetch/drawer-open/expert-v0", ["demo_0", "demo_1", "demo_2"]),
                              ("fetch/drawer-open/expert-valid-v0", valid),
                              ("fetch/drawer-open/mixed-all-v0", ["demo_0", "demo_1", "demo_2", "demo_3"])):
        assert f"as Minari dataset {dataset_id} " in out
        loaded = minari.load_dataset(dataset_id)
        assert [m["demo"] for m in loaded.storage.get_episode_metadata(range(loaded.total_episodes))] == demos


def test_a_fresh_process_recovers_the_env_without_importing_fetch(dataset: pathlib.Path,
                                                                   minari_root: pathlib.Path) -> None:
    export_minari(dataset, "fetch/drawer-open/expert-v0")
    code = ("import sys, minari; d = minari.load_dataset('fetch/drawer-open/expert-v0'); "
            "assert 'fetch' not in sys.modules; e = d.recover_environment(eval_env=True); "
            "o, _ = e.reset(seed=0); print(e.spec.id, o['observation'].shape)")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split()[0] == ENV


def test_cli_export_minari_refuses_an_existing_id_unless_forced(dataset: pathlib.Path, minari_root: pathlib.Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(dataset), "--to", "minari"]) == 0  # default id: fetch/<task>/<device>-v0
    assert "fetch/drawer-open/expert-v0" in capsys.readouterr().out
    assert (minari_root / "fetch/drawer-open/expert-v0/data/main_data.hdf5").exists()
    assert main(["export", str(dataset), "--to", "minari", "--dataset-id", "fetch/drawer-open/expert-v0"]) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and "--force" in err
    assert minari.load_dataset("fetch/drawer-open/expert-v0").total_episodes == 3  # untouched
    assert main(["export", str(dataset), "--to", "minari", "--dataset-id", "fetch/drawer-open/expert-v0", "--demos",
                 "all", "--force"]) == 0
    replaced = minari.load_dataset("fetch/drawer-open/expert-v0")
    assert replaced.total_episodes == 4
    assert replaced.storage.metadata["algorithm_name"] == "expert, scripted"
    failed = replaced[3]
    assert failed.truncations[-1] and len(failed) == int(MAX_STEPS) and not failed.infos["is_success"].any()


def test_cli_export_bad_input_is_a_clear_error(dataset: pathlib.Path, minari_root: pathlib.Path,
                                               tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(tmp_path / "missing.hdf5"), "--to", "minari"]) == 2
    assert "no such file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["export", str(dataset), "--to", "parquet"])
    assert exit_.value.code == 2 and "invalid choice: 'parquet'" in capsys.readouterr().err
    assert main(["export", str(dataset), "--to", "minari", "--demos", "succesful"]) == 2
    err = capsys.readouterr().err
    assert "unknown demo selection 'succesful'" in err and "successful, all, failed, train, valid" in err
    assert main(["export", str(dataset), "--to", "minari", "--dataset-id", "drawer open"]) == 2
    assert "(namespace/)name-v<version>" in capsys.readouterr().err
    assert main(["export", str(dataset), "--to", "minari", "--dataset-id", "fetch/drawer"]) == 2  # no version
    assert main(["export", str(dataset), "--to", "npz"]) == 2
    assert "needs --out" in capsys.readouterr().err
    assert main(["export", str(dataset), "--to", "minari", "--out", str(tmp_path)]) == 2
    assert "--out is for --to npz" in capsys.readouterr().err
    assert main(["export", str(dataset), "--to", "npz", "--out", str(tmp_path / "npz"), "--author", "me"]) == 2
    assert "--author is for --to minari" in capsys.readouterr().err  # was silently dropped
    assert not (tmp_path / "npz").exists()
    assert not any(minari_root.rglob("main_data.hdf5"))  # nothing half-written


def test_every_exporter_reads_options_the_subcommand_has() -> None:
    """The registry and the parser agree: every option an exporter reads or needs is one of `export`'s."""
    from fetch.cli import _parser
    from fetch.dataset.exports.exporters import EXPORTERS, OPTIONS, ExportRequest

    export = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction)).choices["export"]
    dests = {a.dest for a in export._actions}
    assert {e.name for e in EXPORTERS} == set(next(a for a in export._actions if a.dest == "to").choices)
    for e in EXPORTERS:
        assert set(e.reads) | set(e.needs) <= dests, e.name
    # `gym-fetch export` builds its request from the flags of the fields' names
    fields = {f.name for f in dataclasses.fields(ExportRequest)}
    assert fields <= dests and set(OPTIONS) <= fields


def test_an_export_request_is_checked_without_a_command_line(dataset: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """The library takes a typed request: a missing or foreign option is refused before anything is written."""
    from fetch.dataset.exports.exporters import ExportRequest, export

    with pytest.raises(FetchError, match="needs --out"):
        export(ExportRequest(str(dataset), "npz"))
    with pytest.raises(FetchError, match="--author is for --to minari"):
        export(ExportRequest(str(dataset), "npz", out=str(tmp_path / "npz"), author="me"))
    assert not (tmp_path / "npz").exists()
    assert "as npz files in" in export(ExportRequest(str(dataset), "npz", out=str(tmp_path / "npz")))


def test_missing_minari_names_the_extra(dataset: pathlib.Path, minari_root: pathlib.Path,
                                        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "minari", None)  # `import minari` raises ImportError
    assert main(["export", str(dataset), "--to", "minari"]) == 2
    assert 'pip install ".[minari]" (in the gym-fetch-v2 source tree)' in capsys.readouterr().err


def test_npz_export_writes_what_the_collector_writes(dataset: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """The expert is deterministic: a `--format npz` session with the same seeds gives the same files."""
    direct = tmp_path / "direct"
    assert collect(direct, "--format", "npz") == 0
    out = tmp_path / "exported"
    assert main(["export", str(dataset), "--to", "npz", "--out", str(out)]) == 0
    written, expected = sorted(out.glob("*.npz")), sorted(direct.glob("*.npz"))
    stems = [f"{ENV}_ep{i:04d}" for i in range(3)]
    assert [f.name.rsplit("_", 1)[0] for f in written] == [f.name.rsplit("_", 1)[0] for f in expected] == stems
    demos = recorded(dataset)
    for i, (mine, theirs) in enumerate(zip(written, expected, strict=True)):
        a, attrs = demos[f"demo_{i}"]
        assert mine.name == f"{ENV}_ep{i:04d}_{int(attrs['ended'])}.npz"
        with np.load(mine) as m, np.load(theirs) as s:
            assert set(m.files) == set(s.files)
            for key in m.files:
                if key != "metadata_json":
                    assert m[key].dtype == s[key].dtype, key
                    np.testing.assert_array_equal(m[key], s[key], err_msg=key)
            np.testing.assert_array_equal(m["action"], a["actions"])
            np.testing.assert_array_equal(m["expert_action"], a["expert_actions"])  # what to learn (DART)
            np.testing.assert_array_equal(m["obs__observation"][:-1], a["obs/observation"])
            np.testing.assert_array_equal(m["obs__observation"][-1], a["next_obs/observation"][-1])
            np.testing.assert_array_equal(m["states"], a["states"])
            meta, theirs_meta = json.loads(str(m["metadata_json"])), json.loads(str(s["metadata_json"]))
            assert set(theirs_meta) - {"argv", "created_utc"} <= set(meta)
            assert meta["episode_index"] == i and meta["seed"] == attrs["seed"] and meta["successful"] is True
            assert meta["demo"] == f"demo_{i}" and meta["observation_space"] == theirs_meta["observation_space"]


def test_npz_export_refuses_a_directory_that_is_not_empty_unless_forced_and_then_replaces_it(
        dataset: pathlib.Path, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "npz"
    done = export_npz(dataset, out, demos="all")
    assert len(done.demos) == 4 and len(list(out.glob("*.npz"))) == 4
    with np.load(sorted(out.glob("*_ep0003_*.npz"))[0]) as z:
        assert z["truncated"][-1] and not json.loads(str(z["metadata_json"]))["successful"]
    assert main(["export", str(dataset), "--to", "npz", "--out", str(out)]) == 2
    assert "already exists and is not empty" in capsys.readouterr().err
    assert main(["export", str(dataset), "--to", "npz", "--out", str(out), "--demos", "failed", "--force"]) == 0
    with open_dataset(dataset) as ds:
        ended = int(ds.attrs("demo_3")["ended"])
    (only,) = out.glob("*.npz")  # the directory replaced whole: the failed demo alone, numbered from 0
    assert only.name == f"{ENV}_ep0000_{ended}.npz"
    with np.load(only) as z:
        assert json.loads(str(z["metadata_json"]))["demo"] == "demo_3"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["npz"]  # nothing left beside it


def test_a_killed_npz_export_leaves_the_old_directory_or_the_new_one(dataset: pathlib.Path,
                                                                     tmp_path: pathlib.Path) -> None:
    """SIGKILL part-way through: before, 21-58 of 400 files were there; now the old export, whole."""
    import subprocess
    import sys

    out = tmp_path / "npz"
    export_npz(dataset, out, demos="successful")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    killer = ("import os, signal, sys\nfrom fetch import cli\nfrom fetch.dataset import npz\n"
              "inner, calls = npz.seed_file, []\n"
              "def second(*a, **k):\n    calls.append(1)\n"
              "    if len(calls) == 2: os.kill(os.getpid(), signal.SIGKILL)\n    return inner(*a, **k)\n"
              "npz.seed_file = second\nsys.exit(cli.main(sys.argv[1:]))\n")
    run = subprocess.run([sys.executable, "-c", killer, "export", str(dataset), "--to", "npz", "--out", str(out),
                          "--demos", "all", "--force"], capture_output=True, text=True, timeout=300)
    assert run.returncode == -9, run.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert main(["export", str(dataset), "--to", "npz", "--out", str(out), "--demos", "all", "--force"]) == 0
    assert len(list(out.glob("*.npz"))) == 4 and sorted(p.name for p in tmp_path.iterdir()) == ["npz"]


@pytest.fixture(scope="module")
def camera_dataset(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """One expert Reach demo with the front camera's 32-pixel images."""
    src = tmp_path_factory.mktemp("cams")
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "1", "--render", "none",
                 "--cameras", "front", "--image-size", "32", "--out", str(src)]) == 0
    return src


def test_images_are_exported_losslessly(camera_dataset: pathlib.Path, minari_root: pathlib.Path) -> None:
    src = camera_dataset
    export_minari(src, "fetch/reach/cams-v0")
    loaded = minari.load_dataset("fetch/reach/cams-v0")
    space = loaded.observation_space
    assert isinstance(space, gym.spaces.Dict) and space["front_image"].shape == (32, 32, 3)
    with open_dataset(src) as ds:
        a = ds.arrays("demo_0")
    frames = loaded[0].observations["front_image"]
    assert frames.dtype == np.uint8 and frames.any()
    np.testing.assert_array_equal(frames, np.concatenate([a["obs/front_image"], a["next_obs/front_image"][-1:]]))


def test_an_image_export_says_how_to_get_the_images_the_recovered_env_does_not_give(
        camera_dataset: pathlib.Path, minari_root: pathlib.Path) -> None:
    export_minari(camera_dataset, "fetch/reach/cams-v0")
    loaded = minari.load_dataset("fetch/reach/cams-v0")
    description = loaded.storage.metadata["description"]
    recipe = "recover_environment(cameras=('front',), image_size=32, image_quality='fast')"
    assert "state observations only" in description and "front_image" in description and recipe in description
    episode, seed = loaded[0], next(loaded.storage.get_episode_metadata([0]))["seed"]
    for eval_env in (False, True):  # both give the state keys, without a crash
        env = loaded.recover_environment(eval_env=eval_env)
        obs, _ = env.reset(seed=seed)
        assert set(obs) == set(loaded.observation_space.keys()) - {"front_image"}
        env.close()
    env = loaded.recover_environment(cameras=("front",), image_size=32, image_quality="fast")
    frames = [env.reset(seed=seed)[0]["front_image"]]
    for action in episode.actions:
        frames.append(env.step(action)[0]["front_image"])
    env.close()
    np.testing.assert_array_equal(np.stack(frames), episode.observations["front_image"])  # the recipe's images
    export_minari(camera_dataset, "fetch/reach/cams-v0", description="Mine.", force=True)
    description = minari.load_dataset("fetch/reach/cams-v0").storage.metadata["description"]
    assert description.startswith("Mine.") and recipe in description  # the note follows a given description too


def test_a_failed_export_leaves_the_previous_dataset_as_it_was(dataset: pathlib.Path, minari_root: pathlib.Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    import fetch.dataset.exports.export as export

    export_minari(dataset, "fetch/drawer-open/expert-v0")
    before = sorted(p.relative_to(minari_root) for p in minari_root.rglob("*"))

    def broken(*args: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(export, "_episode", broken)
    for dataset_id in ("fetch/drawer-open/expert-v0", "fetch/drawer-open/expert-v1"):
        with pytest.raises(DatasetError, match=f"cannot write the Minari dataset '{dataset_id}' at .*: disk full"):
            export_minari(dataset, dataset_id, demos="all", force=True)
    assert sorted(p.relative_to(minari_root) for p in minari_root.rglob("*")) == before
    assert minari.load_dataset("fetch/drawer-open/expert-v0").total_episodes == 3


def test_a_demo_without_expert_labels_exports_its_applied_actions_as_meant(dataset: pathlib.Path,
                                                                            tmp_path: pathlib.Path) -> None:
    # demo_3 was scripted: no DART noise, so what the device meant is what it applied.
    assert main(["export", str(dataset), "--to", "npz", "--out", str(tmp_path), "--demos", "all"]) == 0
    a, _ = recorded(dataset)["demo_3"]
    assert "expert_actions" not in a
    (last,) = sorted(tmp_path.glob(f"{ENV}_ep0003_*.npz"))
    with np.load(last) as m:
        np.testing.assert_array_equal(m["expert_action"], a["actions"])


def _tree(root: pathlib.Path) -> dict[str, bytes]:
    """Every file under `root`, hidden ones too, with its bytes."""
    return {str(f.relative_to(root)): f.read_bytes() for f in sorted(root.rglob("*")) if f.is_file()}


def test_a_disk_without_room_is_refused_before_anything_is_written(
        dataset: pathlib.Path, minari_root: pathlib.Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Minari's HDF5 writes on a full disk ended in a segfault or an HDF5 traceback: the export checks the
    free space against what it will write first, and the dataset already under the id stays as it was."""
    import fetch.dataset.exports.export as export

    export_minari(dataset, "fetch/drawer-open/expert-v0")
    before = _tree(minari_root)
    with open_dataset(dataset) as ds:
        need = export._space_needed(ds, export.select_demos(ds, "all"))
    recorded_bytes = sum(v.nbytes for a, _ in recorded(dataset).values() for v in a.values())
    assert need > recorded_bytes > sum(f.stat().st_size for f in minari_root.rglob("*") if f.is_file())
    usage = shutil.disk_usage(minari_root)
    monkeypatch.setattr(export.shutil, "disk_usage", lambda path: usage._replace(free=need - 1))
    for dataset_id in ("fetch/drawer-open/expert-v0", "fetch/drawer-open/expert-v1", "new/expert-v0"):
        assert main(["export", str(dataset), "--to", "minari", "--demos", "all", "--dataset-id", dataset_id,
                     "--force"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "not enough disk space" in err and str(minari_root / dataset_id) in err
        assert f"{(need - 1) / 2**20:.1f} MiB free" in err and f"needs about {need / 2**20:.1f} MiB" in err
        assert _tree(minari_root) == before  # nothing created, nothing half-written
    monkeypatch.setattr(export.shutil, "disk_usage", lambda path: usage._replace(free=need))
    assert main(["export", str(dataset), "--to", "minari", "--demos", "all", "--force"]) == 0


def test_a_write_error_inside_minari_is_one_line_and_leaves_the_old_dataset(
        dataset: pathlib.Path, minari_root: pathlib.Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """HDF5 raises RuntimeError on a failed write ("... errno = 28, error message = 'No space left on
    device'"): a one-line error naming the dataset, the staging directory removed, the old dataset kept."""
    from minari.dataset._storages.hdf5_storage import HDF5Storage

    export_minari(dataset, "fetch/drawer-open/expert-v0")
    before = _tree(minari_root)

    def full(*args: object) -> None:
        raise RuntimeError("Can't write data (file write failed: errno = 28,\nerror message = 'No space left')")

    monkeypatch.setattr(HDF5Storage, "update_episodes", full)
    assert main(["export", str(dataset), "--to", "minari", "--force"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "No space left" in err
    assert f"cannot write the Minari dataset 'fetch/drawer-open/expert-v0' at {minari_root}" in err
    assert _tree(minari_root) == before


def test_a_full_file_system_is_refused_with_one_line(dataset: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """On a real file system too small for the export (a tmpfs, mounted in a user namespace: no root
    needed where the kernel allows one), with the dataset already under the id taking part of it."""
    unshare = shutil.which("unshare")
    if unshare is None:
        pytest.skip("no unshare(1) to mount a small tmpfs without root")
    disk = tmp_path / "disk"
    disk.mkdir()
    namespace = [unshare, "--user", "--map-root-user", "--mount", "sh", "-c"]
    probe = subprocess.run([*namespace, f"mount -t tmpfs -o size=64k tmpfs '{disk}'"], capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs in a user namespace here: {probe.stderr.strip()}")
    old = tmp_path / "old"  # an exported dataset, copied onto the small disk as the one under the id
    env = {**os.environ, "MINARI_DATASETS_PATH": str(old)}
    export = [sys.executable, "-c", "import sys; from fetch.cli import main; sys.exit(main(sys.argv[1:]))",
              "export", str(dataset), "--to", "minari", "--dataset-id", "fetch/q/a-v0"]
    assert subprocess.run(export, env=env, capture_output=True).returncode == 0
    script = (f"mount -t tmpfs -o size=512k tmpfs '{disk}' && cp -r '{old}' '{disk}/m' && "
              f"(cd '{disk}' && find . -type f -exec sha256sum {{}} + | sort) > '{tmp_path}/before' && "
              f"MINARI_DATASETS_PATH='{disk}/m' {shlex.join(export)} --force 2> '{tmp_path}/err'; "
              f"echo $? > '{tmp_path}/rc'; (cd '{disk}' && find . -type f -exec sha256sum {{}} + | sort) > "
              f"'{tmp_path}/after'")
    subprocess.run([*namespace, script], env=env, check=True)
    err = (tmp_path / "err").read_text().strip()
    assert (tmp_path / "rc").read_text().strip() == "2", err
    assert len(err.splitlines()) == 1 and "not enough disk space" in err, err
    assert (tmp_path / "after").read_text() == (tmp_path / "before").read_text() != ""


@pytest.mark.parametrize("dataset_id", ["ab/expert-v0", "a/b/expert-v1", "t_/expert-v0", "-x/_y-v2"])
def test_every_dataset_id_minari_reads_back_is_accepted(dataset: pathlib.Path, minari_root: pathlib.Path,
                                                        dataset_id: str) -> None:
    done = export_minari(dataset, dataset_id)
    assert done.path == minari_root / dataset_id and dataset_id in minari.list_local_datasets()
    assert minari.load_dataset(dataset_id).total_episodes == 3


@pytest.mark.parametrize("dataset_id", ["t/abc-v0", "é/x-v0", "a//bc/x-v0", "/x-v0", "ab/x", "ab/x-v0\n",
                                        "ab/x-v0/", "a.b/x-v0", "ab/x-v", "ab/-v0"])
def test_a_dataset_id_minari_cannot_read_back_is_refused(dataset: pathlib.Path, minari_root: pathlib.Path,
                                                         dataset_id: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Minari's own rule (a namespace of at least 2 characters), and where Minari writes what it cannot
    list or load (no version; an empty namespace part), a one-line error before anything is written."""
    assert main(["export", str(dataset), "--to", "minari", "--dataset-id", dataset_id]) == 2
    err = capsys.readouterr().err.strip()
    assert "(namespace/)name-v<version>" in err and "a namespace of at least 2 characters" in err
    assert not minari_root.exists()


def test_the_dataset_id_rule_is_minaris_with_a_version_and_no_empty_part() -> None:
    from minari.dataset.minari_dataset import DATASET_ID_RE

    from fetch.dataset.exports.export import _DATASET_ID

    parts = ["a", "ab", "a/b", "t_", "-", "--", "é", "a//b", "a/", "/a", "x-v0", ""]
    for namespace in parts:
        for name in ("x", "x-y", "x-v0", "-", "é"):
            for version in ("-v0", "-v12", "", "-v"):
                dataset_id = f"{namespace}/{name}{version}" if namespace else f"{name}{version}"
                match = DATASET_ID_RE.fullmatch(dataset_id)
                minaris = match is not None and match["version"] is not None and "//" not in dataset_id
                assert bool(_DATASET_ID.fullmatch(dataset_id)) == minaris, dataset_id


@pytest.mark.parametrize("variable", ["MINARI_DATASETS_PATH", "HF_LEROBOT_HOME", "HF_HOME", "XDG_CACHE_HOME"])
def test_an_empty_output_variable_is_refused_not_read_as_here(dataset: pathlib.Path, tmp_path: pathlib.Path,
                                                               variable: str, monkeypatch: pytest.MonkeyPatch,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Minari and LeRobot read an empty $MINARI_DATASETS_PATH (HF_LEROBOT_HOME, ...) as the current
    directory, which the exports wrote into; it is an error, so that where we write is where they look."""
    here = tmp_path / "here"
    here.mkdir()
    monkeypatch.chdir(here)
    for other in ("HF_LEROBOT_HOME", "HF_HOME", "XDG_CACHE_HOME"):
        monkeypatch.delenv(other, raising=False)
    monkeypatch.setenv(variable, "")
    to = ["minari"] if variable == "MINARI_DATASETS_PATH" else ["lerobot", "--repo-id", "me/x", "--cameras", "none"]
    assert main(["export", str(dataset), "--to", *to]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{variable} is set but empty; unset it" in err, err
    assert not any(here.iterdir())
