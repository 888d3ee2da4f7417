"""No tool writes its output onto what it reads: an --out equal to an input, inside it, or holding it is
refused with one line before anything is written, --force or not (issue: `view D --out D --force` and
`view demos/reach --out demos --force` deleted the dataset)."""

from __future__ import annotations

import hashlib
import pathlib
import shutil

import pytest

from fetch.cli import main


@pytest.fixture(scope="module")
def reach(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("guards") / "demos" / "reach"
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "2", "--render", "none",
                 "--max-steps", "50", "--out", str(out)]) == 0
    return out


def _digest(root: pathlib.Path) -> str:
    """Every file under `root` (names and bytes): what a tool must leave as it was."""
    h = hashlib.sha256()
    for f in sorted(p for p in root.parent.rglob("*") if p.is_file()):
        h.update(str(f.relative_to(root.parent)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def _commands(d: pathlib.Path, out: pathlib.Path) -> list[list[str]]:
    return [["view", str(d), "--out", str(out), "--force"],
            ["export", str(d), "--to", "npz", "--out", str(out), "--force"],
            ["export", str(d), "--to", "lerobot", "--repo-id", "me/reach", "--out", str(out), "--force"],
            ["generate", "--source", str(d), "--out", str(out), "--demos", "2", "--workers", "1"]]


@pytest.mark.parametrize("where", ["same", "index", "inside", "parent"])
def test_an_output_on_its_input_is_refused_and_the_input_is_untouched(reach: pathlib.Path, where: str,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = {"same": reach, "index": reach / "demos.hdf5", "inside": reach / "episodes" / "out",
           "parent": reach.parent}[where]
    before = _digest(reach)
    for command in _commands(reach, out):
        assert main(command) == 2, command
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"--out {out}" in err and "outside the input" in err, (command, err)
        assert _digest(reach) == before, command


@pytest.mark.parametrize("where", ["same", "inside", "parent"])
def test_a_minari_dataset_on_its_input_is_refused_and_the_input_is_untouched(
        reach: pathlib.Path, tmp_path: pathlib.Path, where: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The Minari export writes $MINARI_DATASETS_PATH/<id>: `export D --to minari --dataset-id ID --force`
    with D there deleted D, and a MINARI_DATASETS_PATH inside D was written into."""
    root, dataset_id, at = {"same": (tmp_path, "fetch/q/a-v0", "fetch/q/a-v0"),
                            "inside": (tmp_path / "d" / "minari", "fetch/reach/expert-v0", "d"),
                            "parent": (tmp_path, "held-v0", "held-v0/reach")}[where]
    given = tmp_path / at
    shutil.copytree(reach, given)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    before = _digest(given)
    for force in ([], ["--force"]):
        assert main(["export", str(given), "--to", "minari", "--dataset-id", dataset_id, *force]) == 2, force
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"the Minari dataset {dataset_id!r} at {root / dataset_id}" in err \
            and "outside the input" in err, (force, err)
        assert _digest(given) == before, force


def test_merge_refuses_to_write_into_an_input(reach: pathlib.Path, tmp_path: pathlib.Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """`merge D E --out D/episodes/demo_1.hdf5 --force` overwrote one of D's demos."""
    other = tmp_path / "other"
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "1", "--render", "none",
                 "--max-steps", "50", "--out", str(other)]) == 0
    capsys.readouterr()
    before = _digest(reach)
    for out in (reach / "episodes" / "demo_1.hdf5", reach / "demos.hdf5", reach / "merged.hdf5"):
        assert main(["merge", str(reach), str(other), "--out", str(out), "--force"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "outside the input" in err, err
    assert _digest(reach) == before
    assert main(["merge", str(reach), str(other), "--out", str(tmp_path / "merged.hdf5")]) == 0


@pytest.mark.parametrize("out", [".", ".."])
def test_the_directory_you_are_in_is_never_replaced(reach: pathlib.Path, tmp_path: pathlib.Path, out: str,
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """`view D --out . --force` and `--out ..` ended in a traceback (an empty name; a busy directory) after
    trying to rename the directory in use aside."""
    here = tmp_path / "work"
    here.mkdir()
    (here / "keep.txt").write_text("mine")
    monkeypatch.chdir(here)
    for command in (["view", str(reach), "--out", out, "--force"],
                    ["export", str(reach), "--to", "lerobot", "--repo-id", "me/reach", "--out", out, "--force"]):
        assert main(command) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "is the directory you are in, or holds it" in err, err
    assert (here / "keep.txt").read_text() == "mine" and sorted(p.name for p in tmp_path.iterdir()) == ["work"]


def test_a_directory_a_killed_replacement_set_aside_is_put_back(tmp_path: pathlib.Path) -> None:
    """Killed between its two renames, a --force replacement (view, the LeRobot and Minari exports) left
    the old directory only as a hidden `.<name>.replaced`, which the next replacement deleted first."""
    from fetch.dataset.dirs import replacing_dir
    from fetch.errors import DatasetError

    aside = tmp_path / ".page.replaced"
    aside.mkdir()
    (aside / "index.html").write_text("the old page")
    with pytest.raises(DatasetError, match="already exists and is not empty"), \
            replacing_dir(tmp_path / "page", force=False):
        pass
    assert (tmp_path / "page" / "index.html").read_text() == "the old page" and not aside.exists()
