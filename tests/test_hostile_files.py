"""A dataset is a stranger's file: its links stay inside its directory, and a FIFO where a file should be
is refused at once rather than blocking every tool forever."""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess
import sys

import h5py
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset


def _gym_fetch(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fetch.cli", *args], capture_output=True, text=True, timeout=120)


def _relink(index: pathlib.Path, name: str, filename: str) -> None:
    with h5py.File(index, "r+") as f:
        old = f["data"].get(name, getlink=True)
        del f["data"][name]
        f["data"][name] = h5py.ExternalLink(filename, old.path)


@pytest.mark.parametrize("where", ["absolute", "above"])
def test_a_link_out_of_the_dataset_is_refused_by_every_reader(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                                             where: str) -> None:
    """`data/demo_1` pointing at a file outside the directory (absolute, or `../`): the tools would read it
    and `merge` would copy it into its output."""
    d = tmp_path / "d"
    shutil.copytree(reach_demos, d)
    outside = tmp_path / "secret.hdf5"
    shutil.copy(d / "episodes" / "demo_1.hdf5", outside)
    (d / "episodes" / "demo_1.hdf5").unlink()
    _relink(d / "demos.hdf5", "demo_1", str(outside) if where == "absolute" else "../secret.hdf5")
    with open_dataset(d) as ds:
        with pytest.raises(Exception, match="outside the dataset's directory"):
            ds.arrays("demo_1")
        ds.arrays("demo_0")  # the others still read
    info = _gym_fetch("info", str(d))
    assert info.returncode == 1 and "outside the dataset's directory" in info.stdout + info.stderr
    merged = _gym_fetch("merge", str(d), str(reach_demos), "--out", str(tmp_path / "m.hdf5"))
    assert merged.returncode == 2 and "outside the dataset's directory" in merged.stderr
    assert len(merged.stderr.strip().splitlines()) == 1 and not (tmp_path / "m.hdf5").exists()


def test_a_fifo_for_the_index_or_a_demo_is_refused_not_waited_on(reach_demos: pathlib.Path,
                                                                  tmp_path: pathlib.Path) -> None:
    d = tmp_path / "d"
    shutil.copytree(reach_demos, d)
    (d / "episodes" / "demo_1.hdf5").unlink()
    os.mkfifo(d / "episodes" / "demo_1.hdf5")
    info = _gym_fetch("info", str(d))  # would block forever opening the FIFO
    assert info.returncode == 1 and "not a regular file" in info.stdout + info.stderr
    e = tmp_path / "e"
    e.mkdir()
    os.mkfifo(e / "demos.hdf5")
    for args in (["info", str(e)], ["replay", str(e), "--check"], ["view", str(e), "--out", str(tmp_path / "v")]):
        done = _gym_fetch(*args)
        assert done.returncode == 2 and "is not a regular file" in done.stderr, (args, done.stderr)
        assert len(done.stderr.strip().splitlines()) == 1


def test_the_valid_dataset_still_reads(reach_demos: pathlib.Path) -> None:
    assert main(["info", str(reach_demos)]) == 0
