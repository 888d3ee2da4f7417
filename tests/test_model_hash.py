"""A dataset's model hash names the model, not where its files are installed: datasets from two installs
append to and merge with each other, and datasets stamped the old way still take appends and merge."""

from __future__ import annotations

import pathlib
import shutil
from collections.abc import Iterator

import gymnasium as gym
import h5py
import pytest

from fetch import compiled, scene
from fetch.cli import main
from fetch.dataset import open_dataset

ENV_ID = "Reach-v2"


@pytest.fixture
def fresh_compile() -> Iterator[None]:
    """Scenes compiled in the test are not left in the process-wide caches."""
    compiled.compiled_task.cache_clear()
    compiled.portable_hash.cache_clear()
    yield
    compiled.compiled_task.cache_clear()
    compiled.portable_hash.cache_clear()


def collect(out: pathlib.Path) -> None:
    assert main(["collect", "--env", ENV_ID, "--device", "expert", "--episodes", "1", "--render", "none",
                 "--out", str(out)]) == 0


def stamp_the_old_way(path: pathlib.Path) -> None:
    """Overwrite a dataset's model hash with the pre-portable one (the MJB with absolute file paths)."""
    with h5py.File(path / "demos.hdf5", "r+") as f:
        f["data"].attrs["model_hash"] = gym.make(ENV_ID).unwrapped.legacy_model_hash()


def test_the_same_model_installed_elsewhere_has_the_same_hash(tmp_path: pathlib.Path, fresh_compile: None,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    here = gym.make(ENV_ID).unwrapped
    portable, legacy = here.model_hash(), here.legacy_model_hash()
    elsewhere = tmp_path / "another" / "site-packages" / "assets"
    for part in ("fetch", "stls/fetch", "textures"):
        shutil.copytree(scene.robot_asset_dir() / part, elsewhere / part)
    monkeypatch.setattr(scene, "robot_asset_dir", lambda: elsewhere)
    compiled.compiled_task.cache_clear()
    compiled.portable_hash.cache_clear()
    there = gym.make(ENV_ID).unwrapped
    spec = compiled.compiled_task(type(there.task)).spec
    assert spec.meshdir.startswith(str(elsewhere)), "the scene was not built from the copy"
    if str(elsewhere) in there.model.paths.decode():  # mujoco 4.0 keeps the files' paths in the model, 3.3 did not
        assert there.legacy_model_hash() != legacy, "the old hash depended on the install path"
    assert there.model_hash() == portable


def test_a_dataset_stamped_the_old_way_takes_appends_and_its_stamp_is_renewed(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "old"
    collect(out)
    stamp_the_old_way(out)  # the same as the new stamp on a mujoco that keeps no file paths in the model
    collect(out)
    with open_dataset(out) as ds:
        assert len(ds.demo_names) == 2
        assert ds.data_attrs["model_hash"] == gym.make(ENV_ID).unwrapped.model_hash()
    assert main(["replay", str(out), "--check"]) == 0


def test_an_old_stamped_dataset_merges_with_a_new_one(tmp_path: pathlib.Path) -> None:
    old, new, merged = tmp_path / "old", tmp_path / "new", tmp_path / "merged.hdf5"
    collect(old)
    collect(new)
    stamp_the_old_way(old)
    assert main(["merge", str(old), str(new), "--out", str(merged)]) == 0
    with open_dataset(merged) as ds:
        assert len(ds.demo_names) == 2
        assert ds.data_attrs["model_hash"] == gym.make(ENV_ID).unwrapped.model_hash()
    assert main(["replay", str(merged), "--check"]) == 0


def test_datasets_of_different_models_still_do_not_merge(tmp_path: pathlib.Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    collect(a)
    collect(b)
    with h5py.File(b / "demos.hdf5", "r+") as f:
        f["data"].attrs["model_hash"] = "0" * 64
    assert main(["merge", str(a), str(b), "--out", str(tmp_path / "m.hdf5")]) == 2
    assert "model_hash" in capsys.readouterr().err
