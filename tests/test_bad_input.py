"""Bad command lines get one clear error line and exit 2, and write nothing."""

from __future__ import annotations

import pathlib

import pytest

from fetch.cli import main


@pytest.mark.parametrize(("argv", "says"), [
    (["replay", "{d}", "--demo", "abc"], "neither an index nor a demo name"),
    (["replay", "{d}", "--video", "{t}/v.gif", "--fps", "nan"], "--fps must be a positive"),
    (["replay", "{d}", "--video", "{t}/v.gif", "--fps", "-5"], "--fps must be a positive"),
    (["merge", "{d}", "{d}/", "--out", "{t}/m.hdf5"], "same dataset"),
    (["collect", "--env", "Reach-v2", "--device", "expert", "--render", "none", "--out", ""], "--out must name"),
    (["collect", "--env", "Reach-v2", "--device", "expert", "--render", "none", "--out", "{t}/c",
      "--cameras", "front,front"], "--cameras names front more than once"),
    (["collect", "--env", "Reach-v2", "--device", "expert", "--render", "none", "--out", "{t}/c",
      "--cameras", "front", "--image-size", "100000"], "--image-size must be a whole number of pixels from 1 to"),
    (["collect", "--env", "Reach-v2", "--device", "expert", "--render", "none", "--out", "{t}/c",
      "--max-steps", str(10**12)], "--max-steps must be at most"),
    (["collect", "--env", "Reach-v2", "--device", "expert", "--render", "none", "--out", "{t}/c",
      "--control-hz", "1e-300"], "--control-hz must be 0 (as fast as possible) or a rate from"),
    (["render-obs", "{d}", "--camera", "front", "--workers", "0"], "--workers must be at least 1"),
    (["render-obs", "{d}", "--camera", "front", "--size", "100000"], "--size must be a whole number of pixels"),
    (["split", "{d}", "--seed", "-1"], "--seed must be a whole number from 0"),
    (["view", "{d}", "--out", "{t}/v", "--size", "100000"], "--size must be a whole number of pixels"),
    (["replay", "{d}", "--video", "{t}/v.gif", "--size", "100000"], "--size must be a whole number of pixels"),
    (["split", "{t}/missing.hdf5"], "missing.hdf5"),
    (["render-obs", "{t}/missing.hdf5", "--camera", "front"], "missing.hdf5"),
    (["export", "{d}", "--to", "minari", "--dataset-id", ""], "--dataset-id is empty"),
    (["export", "{d}", "--to", "lerobot", "--repo-id", "me/x", "--out", "{t}/lr", "--cameras", "front,front"],
     "--cameras names front more than once"),
    (["generate", "--source", "{d}", "--out", "{t}/g", "--demos", "2", "--max-steps", str(10**9)],
     "--max-steps must be at most"),
])
def test_bad_arguments_are_one_line_errors(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                           capsys: pytest.CaptureFixture[str], argv: list[str], says: str) -> None:
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main([a.format(d=reach_demos, t=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert code == 2
    assert says in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written
