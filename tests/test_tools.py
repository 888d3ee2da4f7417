"""Dataset tools on small real datasets: replay --video, render-obs, merge, split."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset, schema, validate
from fetch.dataset.background import BackgroundWriter
from fetch.dataset.render.frames import StateRenderer
from fetch.dataset.render.video import read_video
from procs import children, command_line
from robomimic_rules import assert_robomimic_loadable

ENV = "Reach-v2"  # the quickest expert: a few short demos take a second


def collect(out: pathlib.Path, *extra: str, env: str = ENV, episodes: int = 3, seed: int = 0) -> None:
    assert main(["collect", "--env", env, "--device", "expert", "--episodes", str(episodes), "--render", "none",
                 "--seed", str(seed), "--out", str(out), *extra]) == 0


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> dict[str, pathlib.Path]:
    """Datasets made once: `plain` (3 demos), `other` (2 more, other seeds), and `recorded`: the
    same 3 demos as `plain` with the front camera recorded live at 32 px."""
    root = tmp_path_factory.mktemp("tools")
    out = {"plain": root / "plain", "other": root / "other", "recorded": root / "recorded"}
    collect(out["plain"])
    collect(out["other"], episodes=2, seed=100)
    collect(out["recorded"], "--cameras", "front", "--image-size", "32")
    return out


@pytest.fixture
def plain(made: dict[str, pathlib.Path], tmp_path: pathlib.Path) -> pathlib.Path:
    shutil.copytree(made["plain"], tmp_path / "plain")
    return tmp_path / "plain"


def everything(path: pathlib.Path) -> dict[str, object]:
    """Every array and attribute of a dataset, by demo, for before/after comparisons."""
    out: dict[str, object] = {}
    with open_dataset(path) as ds:
        out["data"] = {k: v for k, v in ds.data_attrs.items() if k != "layout"}
        for name in ds.demo_names:
            out[f"{name} attrs"] = ds.attrs(name)
            for key, value in ds.arrays(name).items():
                out[f"{name}/{key}"] = value
    return out


def assert_same(a: dict[str, object], b: dict[str, object], skip: tuple[str, ...] = ()) -> None:
    """Equal keys and values, leaving out keys that contain any of `skip`."""
    kept = [k for k in a if not any(s in k for s in skip)]
    assert kept and set(kept) == {k for k in b if not any(s in k for s in skip)}
    for key in kept:
        if isinstance(a[key], np.ndarray):
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)  # type: ignore[arg-type]
        else:
            assert a[key] == b[key], key


# -- replay --video -----------------------------------------------------------------------------

@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_video_has_a_frame_per_state_showing_the_demo(made: dict[str, pathlib.Path], tmp_path: pathlib.Path,
                                                      suffix: str, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / f"demo{suffix}"
    assert main(["replay", str(made["plain"]), "--demo", "1", "--video", str(out), "--size", "96"]) == 0
    assert "demo_1:" in capsys.readouterr().out
    frames, fps = read_video(out)
    with open_dataset(made["plain"]) as ds, StateRenderer(ds.env_id, ds.env_kwargs, 96, 96) as renderer:
        states = ds.demo("demo_1")["states"][()]
        expected = renderer.frames(states, "front")
    assert frames.shape == expected.shape and fps == 25.0
    # Lossy codecs: each decoded frame is close to its own state's image and farther from the others'.
    error = np.abs(frames.astype(np.int16) - expected.astype(np.int16)).mean(axis=(1, 2, 3))
    assert error.max() < (6.0 if suffix == ".mp4" else 20.0), error
    moved = np.abs(expected[0].astype(np.int16) - expected[-1].astype(np.int16)).mean()
    first_vs_last = np.abs(frames[0].astype(np.int16) - expected[-1].astype(np.int16)).mean()
    assert moved > 0.5 and first_vs_last > error[0]


def test_mp4_is_plain_h264_in_yuv420p(made: dict[str, pathlib.Path], tmp_path: pathlib.Path) -> None:
    import av

    out = tmp_path / "v.mp4"
    assert main(["replay", str(made["plain"]), "--demo", "0", "--video", str(out), "--size", "64", "--fps",
                 "10"]) == 0
    with av.open(str(out)) as container:
        stream = container.streams.video[0]
        assert container.format.name.startswith("mov,mp4")
        assert stream.codec_context.name == "h264" and stream.codec_context.pix_fmt == "yuv420p"
        assert float(stream.average_rate) == 10.0


def test_video_of_several_demos_writes_a_file_each(made: dict[str, pathlib.Path], tmp_path: pathlib.Path) -> None:
    assert main(["replay", str(made["plain"]), "--video", str(tmp_path / "all.gif"), "--size", "32"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["all_demo_0.gif", "all_demo_1.gif", "all_demo_2.gif"]


@pytest.mark.parametrize("args, problem", [
    (["--video", "{tmp}/v.avi"], "unknown video format '.avi'; known: .mp4, .gif"),
    (["--video", "{tmp}/v.mp4", "--size", "81"], "needs an even width and height, got 81x81"),
    (["--video", "{tmp}/v.mp4", "--camera", "top"], "unknown camera 'top'; known: front, "),
    (["--video", "{tmp}/v.mp4", "--demo", "9"], "has no demo 'demo_9'; it has 3 demos"),
    (["--video", "{tmp}/no/such/dir/v.mp4"], "does not exist"),
])
def test_bad_video_arguments_are_named_and_write_nothing(made: dict[str, pathlib.Path], tmp_path: pathlib.Path,
                                                         args: list[str], problem: str,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["replay", str(made["plain"]), *[a.format(tmp=tmp_path) for a in args]]
    assert main(argv) == 2
    assert problem in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# -- render-obs ---------------------------------------------------------------------------------

def test_render_obs_adds_exactly_the_images_collect_records(made: dict[str, pathlib.Path], plain: pathlib.Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    before = everything(plain)
    assert main(["render-obs", str(plain), "--camera", "front", "--size", "32", "--workers", "2"]) == 0
    assert "rendered front for 3 demo(s)" in capsys.readouterr().out
    after = everything(plain)
    assert_same(before, {k: v for k, v in after.items() if "front_image" not in k})  # nothing else changed
    live = everything(made["recorded"])  # same seeds, same expert, images recorded during collection
    for key in [k for k in after if "front_image" in k]:
        np.testing.assert_array_equal(after[key], live[key], err_msg=key)  # type: ignore[arg-type]
    assert len([k for k in after if "front_image" in k]) == 6
    with open_dataset(plain) as ds:
        assert validate(ds) == [] and ds.layout.cameras == ("front",) and ds.layout.image_size == 32
    assert_robomimic_loadable(plain / "demos.hdf5", ("observation", "front_image"))
    assert main(["replay", str(plain)]) == 0  # still replays exactly


def render_obs_killing_workers(path: pathlib.Path, kills: int) -> tuple[subprocess.CompletedProcess[str], int]:
    """`render-obs` on `path` in a process whose render workers are killed (SIGKILL, as the kernel's
    out-of-memory killer would) as they start, `kills` times at most: (its result, how many were killed)."""
    command = [sys.executable, "-m", "fetch.cli", "render-obs", str(path), "--camera", "front", "--size", "32",
               "--workers", "1"]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed: set[int] = set()
    deadline = time.monotonic() + 120
    while len(killed) < kills and proc.poll() is None and time.monotonic() < deadline:
        for pid in children(proc.pid) - killed:
            if "spawn_main" in command_line(pid):  # a worker, not multiprocessing's resource tracker
                os.kill(pid, signal.SIGKILL)
                killed.add(pid)
        time.sleep(0.01)
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise AssertionError(f"render-obs hung after {len(killed)} of its workers were killed") from None
    return subprocess.CompletedProcess(command, proc.returncode, out, err), len(killed)


def test_render_obs_starts_its_workers_again_when_one_is_killed(made: dict[str, pathlib.Path],
                                                                plain: pathlib.Path) -> None:
    """The run starts new workers, renders the demos it had not written, and ends with the same images
    as an undisturbed one."""
    result, killed = render_obs_killing_workers(plain, kills=1)
    assert killed == 1 and result.returncode == 0, result.stderr[-500:]
    assert "a render worker died while rendering demo_0; starting new workers to render it again" in result.stderr
    assert "rendered front for 3 demo(s)" in result.stdout
    after, live = everything(plain), everything(made["recorded"])
    for key in [k for k in after if "front_image" in k]:
        np.testing.assert_array_equal(after[key], live[key], err_msg=key)  # type: ignore[arg-type]
    assert len([k for k in after if "front_image" in k]) == 6


def test_render_obs_gives_up_with_the_dataset_unchanged_when_its_workers_keep_dying(plain: pathlib.Path) -> None:
    before = everything(plain)
    result, killed = render_obs_killing_workers(plain, kills=3)
    assert killed == 3 and result.returncode == 2, result.stderr[-500:]
    assert "a render worker died while rendering demo_0, after 2 restarts" in result.stderr
    assert "Traceback" not in result.stderr
    assert_same(before, everything(plain))


def test_render_obs_adds_a_second_camera_and_refuses_a_second_size(plain: pathlib.Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["render-obs", str(plain), "--camera", "front", "--size", "16", "--workers", "1"]) == 0
    assert main(["render-obs", str(plain), "--camera", "wrist", "--size", "24"]) == 2
    assert "holds 16-pixel images (front); a dataset has one image size, so use --size 16" in capsys.readouterr().err
    assert main(["render-obs", str(plain), "--camera", "front", "--size", "16"]) == 2
    assert "already has front_image; pass --overwrite" in capsys.readouterr().err
    assert main(["render-obs", str(plain), "--camera", "wrist", "--workers", "1"]) == 0  # no --size: the dataset's
    with open_dataset(plain) as ds:
        assert validate(ds) == [] and ds.layout.cameras == ("front", "wrist")
        assert ds.demo("demo_2")["next_obs/wrist_image"].shape[1:] == (16, 16, 3)


def test_render_obs_bounds_the_size_it_takes_from_the_dataset(plain: pathlib.Path, monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """Without --size the dataset's image size is used, under the bound --size has (lowered here below the
    dataset's 72 px, above the envs' default 64: a stranger's dataset of images larger than
    `rendering.MAX_IMAGE_SIZE` is refused alike)."""
    from fetch import rendering

    assert main(["render-obs", str(plain), "--camera", "front", "--size", "72", "--workers", "1"]) == 0
    before = everything(plain)
    monkeypatch.setattr(rendering, "MAX_IMAGE_SIZE", 70)
    assert main(["render-obs", str(plain), "--camera", "wrist", "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "image size must be a whole number of pixels from 1 to 70, got 72" in err, err
    assert_same(before, everything(plain))


def test_render_obs_failure_leaves_the_dataset_as_it_was(plain: pathlib.Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    with h5py.File(plain / "episodes" / "demo_2.hdf5", "r+") as f:  # a state the env cannot restore
        states = f["demo_2/states"][()]
        del f["demo_2/states"]
        f["demo_2/states"] = states[:, :-1]
    before = everything(plain)
    index = (plain / "demos.hdf5").read_bytes()
    assert main(["render-obs", str(plain), "--camera", "front", "--size", "16"]) == 2
    assert "demo_2: states has shape" in capsys.readouterr().err  # refused before any rendering
    assert (plain / "demos.hdf5").read_bytes() == index
    assert_same(before, everything(plain))
    assert not [p for p in plain.rglob("*.tmp")]


def test_render_obs_failing_midway_leaves_the_dataset_as_it_was(plain: pathlib.Path,
                                                                 capsys: pytest.CaptureFixture[str],
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    from fetch.dataset.replay import render_obs
    from fetch.errors import DatasetError

    store = render_obs._store
    stored: list[str] = []

    def store_then_fail(group: h5py.Group, key: str, images: np.ndarray) -> None:
        if stored:  # the second demo: the first one's copy is already edited
            raise DatasetError("the disk is full (simulated)")
        stored.append(group.name)
        store(group, key, images)

    monkeypatch.setattr(render_obs, "_store", store_then_fail)
    before = everything(plain)
    index = (plain / "demos.hdf5").read_bytes()
    assert main(["render-obs", str(plain), "--camera", "front", "--size", "16", "--workers", "1"]) == 2
    assert "disk is full" in capsys.readouterr().err and stored
    assert (plain / "demos.hdf5").read_bytes() == index
    assert_same(before, everything(plain))
    assert not [p for p in plain.rglob("*.tmp")]


@pytest.mark.parametrize("command", [["render-obs", "--camera", "front", "--size", "16"], ["split", "--valid", "0.5"]])
def test_tools_that_edit_wait_for_the_collector(plain: pathlib.Path, command: list[str],
                                                capsys: pytest.CaptureFixture[str]) -> None:
    index = (plain / "demos.hdf5").read_bytes()
    collector = BackgroundWriter(plain, on_saved=None)  # holds the directory's lock as a collector does
    try:
        assert main([command[0], str(plain), *command[1:]]) == 2
        assert "in use by another collector or tool" in capsys.readouterr().err
    finally:
        collector._unlock()
    assert (plain / "demos.hdf5").read_bytes() == index
    assert main([command[0], str(plain), *command[1:]]) == 0


@pytest.mark.parametrize("args, problem", [
    (["--camera", "nope"], "unknown camera 'nope'; known: front"),
    (["--camera", "front", "--size", "0"], "--size must be a whole number of pixels from 1 to 2048"),
    (["--camera", "front", "--workers", "-1"], "--workers must be at least 1"),
])
def test_bad_render_obs_arguments_are_named(plain: pathlib.Path, args: list[str], problem: str,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    index = (plain / "demos.hdf5").read_bytes()
    assert main(["render-obs", str(plain), *args]) == 2
    assert problem in capsys.readouterr().err
    assert (plain / "demos.hdf5").read_bytes() == index


# -- merge --------------------------------------------------------------------------------------

def test_merge_renumbers_keeps_everything_and_stands_alone(made: dict[str, pathlib.Path], tmp_path: pathlib.Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "merged.hdf5"
    assert main(["merge", str(made["plain"]), str(made["other"]), "--out", str(out)]) == 0
    assert "5 demos" in capsys.readouterr().out
    a, b, m = everything(made["plain"]), everything(made["other"]), everything(out)
    for i, (source, name) in enumerate([(a, f"demo_{j}") for j in range(3)] + [(b, f"demo_{j}") for j in range(2)]):
        for key in [k for k in source if k.startswith(f"{name}/")]:
            np.testing.assert_array_equal(m[key.replace(name, f"demo_{i}", 1)], source[key])  # type: ignore
        attrs = dict(m[f"demo_{i} attrs"])  # type: ignore[call-overload]
        assert attrs.pop("source").endswith(f"demos.hdf5:{name}")
        assert attrs == source[f"{name} attrs"]
    with open_dataset(out) as ds:
        assert validate(ds) == [] and ds.demo_names == [f"demo_{i}" for i in range(5)]
        assert ds.data_attrs["total"] == sum(int(ds.attrs(n)["num_samples"]) for n in ds.demo_names)
        assert len(json.loads(ds.data_attrs["sources"])) == 2
        assert sorted(sum(ds.masks().values(), [])) == sorted(ds.demo_names)
    moved = tmp_path / "elsewhere" / "copy.hdf5"  # self-contained: copying the one file is enough
    moved.parent.mkdir()
    shutil.copyfile(out, moved)
    assert main(["replay", str(moved)]) == 0
    assert "5 exact" in capsys.readouterr().out
    assert_robomimic_loadable(moved)


def test_merged_file_takes_render_obs_and_split_but_not_a_collector(made: dict[str, pathlib.Path],
                                                                    tmp_path: pathlib.Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "m.hdf5"
    assert main(["merge", str(made["plain"]), str(made["other"]), "--out", str(out)]) == 0
    assert main(["render-obs", str(out), "--camera", "front", "--size", "32", "--workers", "2"]) == 0
    live = everything(made["recorded"])
    with open_dataset(out) as ds:
        assert validate(ds) == []
        np.testing.assert_array_equal(ds.demo("demo_1")["obs/front_image"][()], live["demo_1/obs/front_image"])
    assert main(["split", str(out), "--valid", "0.4"]) == 0
    capsys.readouterr()
    merged_dir = tmp_path / "mdir"
    merged_dir.mkdir()
    shutil.copyfile(out, merged_dir / "demos.hdf5")
    before = (merged_dir / "demos.hdf5").read_bytes()
    assert main(["collect", "--env", ENV, "--device", "expert", "--episodes", "1", "--render", "none", "--cameras",
                 "front", "--image-size", "32", "--out", str(merged_dir)]) == 2
    assert "collector cannot append to it" in capsys.readouterr().err
    assert (merged_dir / "demos.hdf5").read_bytes() == before


def test_merge_refuses_what_does_not_belong_together(made: dict[str, pathlib.Path], tmp_path: pathlib.Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "m.hdf5"
    assert main(["merge", str(made["plain"]), str(made["recorded"]), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "cannot be merged" in err and "layout" in err and not out.exists()
    drawer = tmp_path / "drawer"
    collect(drawer, env="Drawer-open-v2", episodes=1)
    assert main(["merge", str(made["plain"]), str(drawer), "--out", str(out)]) == 2
    assert "env_id: " in capsys.readouterr().err and not out.exists()
    assert main(["merge", str(made["plain"]), "--out", str(out)]) == 2
    assert "at least two datasets" in capsys.readouterr().err
    assert main(["merge", str(made["plain"]), str(made["other"]), "--out", str(tmp_path)]) == 2
    assert "is a directory; merge writes one file" in capsys.readouterr().err
    out.write_bytes(b"precious")
    assert main(["merge", str(made["plain"]), str(made["other"]), "--out", str(out)]) == 2
    assert "exists; pass --force" in capsys.readouterr().err and out.read_bytes() == b"precious"
    assert main(["merge", str(made["plain"]), str(made["other"]), "--out", str(out), "--force"]) == 0
    assert main(["merge", str(made["plain"]), str(tmp_path / "missing"), "--out", str(out), "--force"]) == 2
    assert "missing" in capsys.readouterr().err


# -- split --------------------------------------------------------------------------------------

def test_split_draws_the_valid_fraction_by_seed_and_keeps_failures_apart(tmp_path: pathlib.Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "d"
    collect(out, episodes=10)
    script = tmp_path / "fail.json"  # two attempts that end without success (B), kept as failures
    idle = {"action": [0, 0, 0, 0]}
    script.write_text(json.dumps([idle, idle, {"finish": True}, idle, {"finish": True}, {"quit": True}]))
    assert main(["collect", "--env", ENV, "--device", "scripted", "--scripted-json", str(script),
                 "--keep-failures", "--render", "none", "--out", str(out)]) == 0

    def masks() -> dict[str, list[str]]:
        with open_dataset(out) as ds:
            assert validate(ds) == []
            return ds.masks()

    assert main(["split", str(out), "--valid", "0.3", "--seed", "1"]) == 0
    assert "train 7, valid 3, failed 2" in capsys.readouterr().out
    first = masks()
    assert main(["split", str(out), "--valid", "0.3", "--seed", "1"]) == 0
    assert masks() == first
    assert main(["split", str(out), "--valid", "0.3", "--seed", "2"]) == 0
    second = masks()
    assert second["valid"] != first["valid"] and second["failed"] == first["failed"]
    assert not set(second["failed"]) & set(second["train"] + second["valid"])
    collect(out, episodes=1)  # a resumed collector keeps the split and places its new demo
    third = masks()
    assert set(second["valid"]) <= set(third["valid"]) and set(second["train"]) <= set(third["train"])
    assert main(["split", str(out), "--valid", "0"]) == 0
    assert masks()["valid"] == []
    assert main(["split", str(out), "--valid", "1"]) == 2
    assert "--valid must be a fraction in [0, 1), got 1.0" in capsys.readouterr().err


# -- collect --cameras ----------------------------------------------------------------------------

def test_images_a_stopped_session_left_unrendered_are_rendered_by_the_next(made: dict[str, pathlib.Path],
                                                                           tmp_path: pathlib.Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "recorded"
    shutil.copytree(made["recorded"], out)
    with h5py.File(out / "episodes" / "demo_1.hdf5", "r+") as f:  # as saved before its images were made
        del f["demo_1/obs/front_image"], f["demo_1/next_obs/front_image"]
    assert main(["info", str(out)]) == 1
    assert "demo_1: its images are not rendered yet" in capsys.readouterr().out
    collect(out, "--cameras", "front", "--image-size", "32", episodes=1, seed=50)
    with open_dataset(out) as ds:
        assert validate(ds) == [] and ds.demo_names == ["demo_0", "demo_1", "demo_2", "demo_3"]
    assert_same(everything(made["recorded"]), everything(out), skip=("demo_3", "data"))


SWALLOWED_IN_TOOL = """
import os, signal, sys, weakref
from fetch import cli
from fetch.dataset import edit, npz
from fetch.dataset.exports import export
from fetch.dataset.replay import render_obs

class Thing:
    pass

def swallowed_ctrl_c():
    # Ctrl-C lands while a weakref callback runs: Python prints the handler's exception as
    # "Exception ignored in ..." and the tool carries on, unless the stop is delivered again.
    thing = Thing()
    ref = weakref.ref(thing, lambda _: os.kill(os.getpid(), signal.SIGINT))
    del thing

def first(module, name):
    inner = getattr(module, name)
    def wrapped(*args, **kwargs):
        swallowed_ctrl_c()
        setattr(module, name, inner)
        return inner(*args, **kwargs)
    setattr(module, name, wrapped)

first(edit, "_write_merged"), first(edit, "write_masks"), first(render_obs, "_store"), first(npz, "seed_file")
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.parametrize("tool", ["merge", "split", "render-obs", "export npz"])
def test_a_stop_whose_exception_python_swallowed_still_stops_the_tool_and_changes_nothing(
        made: dict[str, pathlib.Path], tmp_path: pathlib.Path, tool: str) -> None:
    """A Ctrl-C whose `Stopped` Python swallowed (raised in a weakref callback or `__del__`) still stops an
    editing or exporting tool with 130 before it replaces anything (it used to finish and exit 0), and
    no "Exception ignored" traceback is printed (`stopping._dropped` delivers it again)."""
    import subprocess
    import sys

    shutil.copytree(made["plain"], tmp_path / "plain")
    ds, out = tmp_path / "plain", tmp_path / "out"
    before = {p: p.read_bytes() for p in ds.rglob("*") if p.is_file()}
    out.mkdir()
    args = {"merge": ["merge", str(ds), str(made["other"]), "--out", str(out / "merged.hdf5")],
            "split": ["split", str(ds), "--valid", "0.5"],
            "render-obs": ["render-obs", str(ds), "--camera", "front", "--size", "16", "--workers", "1"],
            "export npz": ["export", str(ds), "--to", "npz", "--out", str(out)]}[tool]
    proc = subprocess.run([sys.executable, "-c", SWALLOWED_IN_TOOL, *args], capture_output=True, text=True,
                          timeout=300)
    assert "Exception ignored in" not in proc.stderr  # not printed: delivered again once out of the callback
    assert proc.returncode == 130, proc.stderr
    assert {p: p.read_bytes() for p in ds.rglob("*") if p.is_file()} == before
    assert not list(out.iterdir())


KILLED_BETWEEN_RENAMES = """
import os, signal, sys
from fetch import cli
from fetch import _durable as durable

replaced = []
real = os.replace
def replace(src, dst):
    if str(dst).endswith(".hdf5"):
        replaced.append(dst)
        if len(replaced) == 2:  # the second demo file renamed: SIGKILL before the rest and the index
            os.kill(os.getpid(), signal.SIGKILL)
    return real(src, dst)
durable.os.replace = replace
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.parametrize("then", ["info", "collect"])
def test_render_obs_killed_between_its_renames_is_finished_by_the_next_tool(plain: pathlib.Path, then: str) -> None:
    """The copies are renamed over the originals one by one; a SIGKILL between two left 2 of 3 demos with
    images and a layout without the camera, which `info` called valid. The renames are noted first, and
    the next tool that opens the dataset (a reader, a resuming collector) makes the rest."""
    proc = subprocess.run([sys.executable, "-c", KILLED_BETWEEN_RENAMES, "render-obs", str(plain), "--camera",
                           "front", "--size", "16", "--workers", "1"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == -9, proc.stderr
    assert (plain / ".demos.hdf5.rewrites").exists()
    if then == "info":
        assert main(["info", str(plain)]) == 0
    else:
        collect(plain, "--cameras", "front", "--image-size", "16", episodes=1, seed=50)  # as the dataset now is
    assert not list(plain.glob(".*")) and not list((plain / "episodes").glob(".*"))
    with open_dataset(plain) as ds:
        assert validate(ds) == [] and "front" in ds.layout.cameras
        assert all(f"obs/{schema.image_key('front')}" in ds.demo(n) for n in ds.demo_names[:3])


@pytest.mark.parametrize("tool", ["info", "split", "export npz"])
def test_a_full_stdout_is_one_line_and_the_work_is_done(plain: pathlib.Path, tmp_path: pathlib.Path, tool: str) -> None:
    """`> /dev/full`: the report's print failed with ENOSPC, a traceback; now one line, exit 1, and what
    the tool did is done (the split written, the export in place)."""
    args = {"info": ["info", str(plain)], "split": ["split", str(plain), "--valid", "0.5"],
            "export npz": ["export", str(plain), "--to", "npz", "--out", str(tmp_path / "npz")]}[tool]
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "fetch.cli", *args], stdout=full, stderr=subprocess.PIPE,
                              text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip() == f"gym-fetch {args[0]}: error: cannot write to stdout (No space left on device)"
    if tool == "split":
        with open_dataset(plain) as ds:
            assert len(ds.masks()["valid"]) >= 1
    if tool == "export npz":
        assert len(list((tmp_path / "npz").glob("*.npz"))) == 3


def test_every_recording_format_has_a_reader() -> None:
    """`info` and `replay` read through `open_recording`: each format `collect --format` writes has a reader."""
    from fetch.dataset.formats import FORMATS
    from fetch.dataset.replay.recordings import READERS

    assert {r.format for r in READERS} == set(FORMATS)
