"""Demos already saved are never overwritten: an index gone missing, a lock file deleted."""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import sys

import pytest

from fetch.cli import main
from procs import alive, children, command_line


def _collect(out: pathlib.Path, episodes: int) -> int:
    return main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", str(episodes),
                 "--render", "none", "--out", str(out)])


def test_episode_files_without_their_index_are_never_overwritten(tmp_path: pathlib.Path, capsys) -> None:
    out = tmp_path / "demos"
    assert _collect(out, 3) == 0
    (out / "demos.hdf5").unlink()
    before = {p.name: p.read_bytes() for p in (out / "episodes").iterdir()}
    capsys.readouterr()
    assert _collect(out, 2) == 2
    assert "3 demo file(s)" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in (out / "episodes").iterdir()} == before
    assert not (out / "demos.hdf5").exists()


def test_a_dangling_index_link_is_refused(tmp_path: pathlib.Path, capsys) -> None:
    out = tmp_path / "demos"
    out.mkdir()
    (out / "demos.hdf5").symlink_to(tmp_path / "elsewhere.hdf5")
    assert _collect(out, 1) == 2  # refused as any link at the index is (docs/security.md), dangling or not
    assert "demos.hdf5 is a symbolic link" in capsys.readouterr().err
    assert (out / "demos.hdf5").is_symlink() and not (tmp_path / "elsewhere.hdf5").exists()


def test_deleting_a_lock_file_does_not_let_a_second_collector_in(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "demos"
    command = [sys.executable, "-u", "-m", "fetch.cli", "collect", "--env", "Reach-v2", "--device", "expert",
               "--render", "none", "--control-hz", "25", "--episodes", "1000", "--out", str(out)]
    first = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert first.stdout is not None
        for line in first.stdout:
            if line.startswith("saved "):
                break
        for path in out.iterdir():  # whatever lock file a collector keeps, gone
            if path.name.startswith(".") and path.is_file():
                path.unlink()
        second = subprocess.run(command, capture_output=True, text=True, timeout=120)
        assert second.returncode == 2, second.stdout[-300:]
        assert "in use by another collector" in second.stderr
    finally:
        first.send_signal(signal.SIGTERM)
        first.communicate(timeout=60)
    assert first.returncode == 128 + signal.SIGTERM


def test_render_workers_die_with_a_killed_collector(tmp_path: pathlib.Path) -> None:
    import time

    command = [sys.executable, "-u", "-m", "fetch.cli", "collect", "--env", "Reach-v2", "--device", "expert",
               "--render", "none", "--episodes", "1000", "--cameras", "front", "--image-size", "32",
               "--out", str(tmp_path / "demos")]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    saves = 0
    for line in proc.stdout:
        saves += line.startswith("saved ")
        if saves >= 2:
            break
    workers = children(proc.pid)
    assert workers, "the collector should have started render workers"
    proc.kill()
    proc.communicate(timeout=30)
    deadline = time.monotonic() + 20
    while any(alive(c) for c in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [c for c in workers if alive(c)], "render workers outlived the collector"


def test_the_collector_replaces_a_render_worker_that_dies(tmp_path: pathlib.Path) -> None:
    """Its camera images are rendered in a worker process after each demo is saved: a worker killed
    (as the out-of-memory killer would) is replaced, and every demo still gets its images."""
    import time

    from fetch.dataset import open_dataset, validate

    out = tmp_path / "demos"
    command = [sys.executable, "-u", "-m", "fetch.cli", "collect", "--env", "Reach-v2", "--device", "expert",
               "--render", "none", "--episodes", "4", "--cameras", "front", "--image-size", "32", "--out", str(out)]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed = None
    deadline = time.monotonic() + 120
    while killed is None and proc.poll() is None and time.monotonic() < deadline:
        for pid in children(proc.pid):
            if "spawn_main" in command_line(pid):  # the render worker, not multiprocessing's resource tracker
                os.kill(pid, signal.SIGKILL)
                killed = pid
                break
        time.sleep(0.01)
    out_text, err = proc.communicate(timeout=120)
    assert killed is not None, "the collector should have started a render worker"
    assert proc.returncode == 0, err[-500:]
    assert "the render worker died while rendering demo_0's images; starting a new one" in err
    with open_dataset(out) as ds:
        assert len(ds.demo_names) == 4 and validate(ds) == []
        for name in ds.demo_names:
            assert ds.demo(name)["next_obs/front_image"].shape[1:] == (32, 32, 3), name


def test_the_writer_falls_at_most_max_queued_demos_behind(tmp_path: pathlib.Path) -> None:
    """A slow disk: commits wait for the writer instead of piling up demos that a crash would lose."""
    import time

    from fetch.dataset.background import MAX_QUEUED, BackgroundWriter
    from fetch.dataset.episode import Demo

    class SlowDisk(BackgroundWriter):
        def _save(self, name: str, demo: Demo) -> None:
            time.sleep(0.02)

    writer = SlowDisk(tmp_path / "out", None)
    writer._start()
    waits = []
    for _ in range(3 * MAX_QUEUED):
        start = time.perf_counter()
        writer.commit(Demo(arrays={}, attrs={}))
        waits.append(time.perf_counter() - start)
        assert writer.behind <= MAX_QUEUED
    writer.close()
    assert writer.saved == 3 * MAX_QUEUED
    assert writer.most_behind == MAX_QUEUED
    assert max(waits) > 0.01  # the last commits waited for the disk


def _tiny_demos(count: int) -> tuple[object, list[object]]:
    """A Reach env and `count` real 3-step demos of it."""
    import gymnasium as gym
    import numpy as np

    from fetch.dataset.episode import EpisodeBuffer
    from fetch.dataset.formats import recorded_layout

    env = gym.make("Reach-v2")
    demos = []
    for seed in range(count):
        buf = EpisodeBuffer(recorded_layout(env), capacity=3)
        obs, _ = env.reset(seed=seed)
        buf.begin(obs, env.unwrapped.get_state())
        for _ in range(3):
            obs, reward, terminated, truncated, info = env.step(np.float32([0.5, 0, 0, 1]))
            env.unwrapped.get_state(out=buf.state_row())
            success = info["is_success"] >= 1  # the reward says so too, and validation holds them together
            buf.record(env.unwrapped.last_action, obs, float(reward), terminated, truncated, success, 0.0)
        demos.append(buf.demo({"seed": seed, "success": False, "env_id": "Reach-v2", "device": "test",
                               "attempt": seed, "control_hz": 0.0, "achieved_hz": 0.0, "started": 0.0,
                               "ended": 0.0}))
    return env, demos


def test_a_fast_writer_rewrites_the_index_in_batches_and_loses_none(tmp_path: pathlib.Path, monkeypatch) -> None:
    """The index costs ~70 us per listed demo to rewrite: rewritten for every demo, 100,000 demos are
    O(N^2). Batched (at 1/8 of the dataset's size), a burst of 64 demos rewrites it far fewer times,
    reports each demo saved only once the index lists it, and the closed dataset lists all 64."""
    from fetch.dataset import open_dataset, validate
    from fetch.dataset.formats import open_writer
    from fetch.dataset.writer import DatasetWriter

    env, demos = _tiny_demos(64)
    rewrites, listed_when_saved = [], []
    original = DatasetWriter._write_index

    def counting(self: DatasetWriter) -> None:
        original(self)
        rewrites.append(len(self._entries))

    monkeypatch.setattr(DatasetWriter, "_write_index", counting)
    writer = open_writer("hdf5", str(tmp_path / "out"), env, settings={"max_steps": 3}, device="test",
                         on_saved=lambda name, demo: listed_when_saved.append(name in _indexed(tmp_path / "out")))
    for demo in demos:
        writer.commit(demo)
    writer.close()
    assert len(listed_when_saved) == 64 and all(listed_when_saved)
    assert len(rewrites) < 40, rewrites  # 64 + 2 before batching
    with open_dataset(tmp_path / "out") as ds:
        assert len(ds.demo_names) == 64 and validate(ds) == []
        assert sorted(ds.masks()["failed"]) == sorted(ds.demo_names)


def test_a_slow_writer_publishes_each_demo_when_idle(tmp_path: pathlib.Path) -> None:
    """A person's demos come seconds apart: each is in the index (and reported saved) within
    IDLE_PUBLISH of its save, without waiting for a batch to fill."""
    import time

    from fetch.dataset.background import IDLE_PUBLISH
    from fetch.dataset.formats import open_writer

    env, demos = _tiny_demos(20)
    saved: list[str] = []
    writer = open_writer("hdf5", str(tmp_path / "out"), env, settings={"max_steps": 3}, device="test",
                         on_saved=lambda name, demo: saved.append(name))
    for demo in demos[:16]:  # a dataset large enough that one demo is under 1/8 of it
        writer.commit(demo)
    writer.flush()
    assert len(saved) == 16
    for i, demo in enumerate(demos[16:]):
        writer.commit(demo)
        time.sleep(IDLE_PUBLISH + 1.0)
        assert len(saved) == 17 + i and f"demo_{16 + i}" in _indexed(tmp_path / "out")
    writer.close()


def _indexed(out: pathlib.Path) -> set[str]:
    import h5py

    with h5py.File(out / "demos.hdf5", "r") as f:
        return set(f["data"].keys())


def test_generate_workers_die_with_a_killed_generate(reach_demos: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """A SIGKILLed `generate --workers 2` left its 2 workers and a resource tracker running for good
    (10 of 10, ~136 MB each)."""
    import time

    command = [sys.executable, "-u", "-m", "fetch.cli", "generate", "--source", str(reach_demos), "--out",
               str(tmp_path / "gen"), "--demos", "100000", "--workers", "2"]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(children(proc.pid)) < 3 and time.monotonic() < deadline:  # 2 workers and the resource tracker
        time.sleep(0.2)
    while not any((tmp_path / "gen" / "episodes").glob("demo_*.hdf5")) and time.monotonic() < deadline:
        time.sleep(0.2)  # the workers are making demos
    started = children(proc.pid)
    assert len(started) >= 3, started
    proc.kill()
    proc.wait(timeout=30)
    deadline = time.monotonic() + 20
    while any(alive(c) for c in started) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [command_line(c) for c in started if alive(c)], "processes outlived a killed generate"


@pytest.mark.parametrize("stdout", ["full", "head"])
def test_a_failing_stdout_neither_hangs_the_collector_nor_loses_a_demo(tmp_path: pathlib.Path, stdout: str) -> None:
    """`collect ... > /dev/full` and `collect ... | head -n 3` hung (the writer thread died printing
    "saved ...", the session waited for it forever; 1 of 20 demos saved)."""
    out = tmp_path / "demos"
    command = (f"{sys.executable} -m fetch.cli collect --env Reach-v2 --device expert --episodes 20 --render none "
               f"--out {out}")
    shell = f"{command} > /dev/full" if stdout == "full" else f"{command} | head -n 3"
    proc = subprocess.Popen(["bash", "-c", shell], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        proc.wait(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the collector too, not only its shell
        proc.wait()
        raise AssertionError("the collector hung") from None
    from fetch.dataset import open_dataset, validate

    with open_dataset(out) as ds:
        assert len(ds.demo_names) == 20 and validate(ds) == []
