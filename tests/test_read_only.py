"""As a user who may not write: a read-only dataset, a read-only output directory, a home without write
access. Every tool refuses in one line before it does any work, exit 2, and changes nothing. Root writes
through any permission, so these run where the suite runs as another user (CI runs it again so)."""

from __future__ import annotations

import os
import pathlib
import shutil
import stat
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                                reason="root writes through any permission; CI runs the suite again as a non-root user")

CASES: dict[str, tuple[list[str], str | None]] = {
    # case: (the command, with {d} the read-only dataset, {o} a writable copy and {r} a read-only empty
    # directory; the module it needs)
    "collect into the dataset": (["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "1",
                                  "--render", "none", "--out", "{d}"], None),
    "render-obs": (["render-obs", "{d}", "--camera", "front", "--size", "16", "--workers", "1"], None),
    "split": (["split", "{d}"], None),
    "merge into it": (["merge", "{o}", "--out", "{d}/merged.hdf5"], None),
    "merge into a read-only directory": (["merge", "{o}", "--out", "{r}/merged.hdf5"], None),
    "npz export": (["export", "{d}", "--to", "npz", "--out", "{r}/npz"], None),
    "minari export, read-only home": (["export", "{d}", "--to", "minari", "--dataset-id", "fetch/ro/test-v0"],
                                      "minari"),
    "lerobot export, read-only home": (["export", "{d}", "--to", "lerobot", "--repo-id", "me/ro", "--cameras",
                                        "none"], "pyarrow"),
    "view": (["view", "{d}", "--out", "{r}/view", "--size", "16", "--workers", "1"], "av"),
    "generate": (["generate", "--source", "{d}", "--out", "{r}/generated", "--demos", "1", "--workers", "1"], None),
}


def _read_only(root: pathlib.Path) -> None:
    for path in [root, *root.rglob("*")]:
        mode = path.stat().st_mode
        path.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))


def _snapshot(root: pathlib.Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(root)): p.read_bytes() if p.is_file() else None for p in sorted(root.rglob("*"))}


@pytest.mark.parametrize("case", list(CASES))
def test_a_tool_that_may_not_write_says_so_in_one_line_and_changes_nothing(reach_demos: pathlib.Path,
                                                                          tmp_path: pathlib.Path, case: str) -> None:
    argv, needs = CASES[case]
    if needs is not None:
        pytest.importorskip(needs)
    data, other, closed, home = tmp_path / "data", tmp_path / "other", tmp_path / "closed", tmp_path / "home"
    shutil.copytree(reach_demos, data)
    shutil.copytree(reach_demos, other)
    closed.mkdir()
    home.mkdir()
    for root in (data, closed, home):
        _read_only(root)
    before = {root.name: _snapshot(root) for root in (data, closed, home)}
    env = {k: v for k, v in os.environ.items()
           if k not in ("MINARI_DATASETS_PATH", "HF_LEROBOT_HOME", "HF_HOME", "XDG_CACHE_HOME")}
    env["HOME"] = str(home)
    try:
        run = subprocess.run([sys.executable, "-m", "fetch.cli", *(a.format(d=data, o=other, r=closed) for a in argv)],
                             capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
    finally:
        for root in (data, closed, home):
            for path in [root, *root.rglob("*")]:
                path.chmod(path.stat().st_mode | stat.S_IWUSR)  # so that pytest can remove them
    said = f"exit {run.returncode}; stdout {run.stdout[-300:]!r}; stderr {run.stderr[-800:]!r}"
    assert run.returncode == 2, said
    assert "Traceback" not in run.stderr, said
    lines = [line for line in run.stderr.strip().splitlines() if not line.startswith("collecting ")]  # its banner
    assert len(lines) == 1 and "error: " in lines[0], said
    assert not run.stdout.count("saved demo_"), f"work was done before the refusal: {said}"
    assert {root.name: _snapshot(root) for root in (data, closed, home)} == before, said
