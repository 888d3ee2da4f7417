"""A collector killed at any instant, or refused disk space, loses no demo it reported as saved."""

from __future__ import annotations

import json
import pathlib
import random
import resource
import signal
import subprocess
import sys
import time

import pytest

from fetch.dataset import open_dataset, validate
from fetch.dataset.replay.check import check_demo


def collector(out: pathlib.Path, *extra: str, env: str = "Reach-v2") -> list[str]:
    return [sys.executable, "-u", "-m", "fetch.cli", "collect", "--env", env, "--render", "none",
            "--out", str(out), *extra]


def saved_names(text: str) -> set[str]:
    return {line.split()[1].rstrip(":") for line in text.splitlines() if line.startswith("saved demo_")}


def test_sigkill_at_random_moments_keeps_every_reported_demo(tmp_path: pathlib.Path) -> None:
    rng = random.Random(7)
    out = tmp_path / "demos"
    reported: set[str] = set()
    for round_ in range(8):
        proc = subprocess.Popen(collector(out, "--device", "expert", "--episodes", "100000"),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert proc.stdout is not None
        if round_ % 2:  # at a random instant after start (import, resume, collecting)
            time.sleep(rng.uniform(0.3, 2.5))
        else:  # a few saves in, a random moment into the next attempt or write
            seen = 0
            target = rng.randint(1, 6)
            for line in proc.stdout:
                reported |= saved_names(line)
                seen += line.startswith("saved ")
                if seen >= target:
                    break
            time.sleep(rng.uniform(0.0, 0.03))
        proc.send_signal(signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=60)
        reported |= saved_names(stdout)
        assert proc.returncode == -signal.SIGKILL, stderr
        if not (out / "demos.hdf5").exists():
            assert not reported  # killed before the dataset was created
            continue
        with open_dataset(out) as ds:
            assert reported <= set(ds.demo_names), sorted(reported - set(ds.demo_names))
            assert validate(ds) == []
    assert len(reported) >= 8, "the kills should land among saves"
    with open_dataset(out) as ds:
        for name in sorted(reported)[:3]:
            assert check_demo(ds, name).exact


def _limit_file_size(limit: int) -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


def test_a_write_failure_is_a_clear_error_and_keeps_earlier_demos(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "demos"
    # The expert with a person's settings (ending at success, 500 steps), so the scripted session may resume.
    first = subprocess.run(collector(out, "--device", "expert", "--episodes", "3", "--stop-on-success",
                                     "--max-steps", "500"), capture_output=True,
                           text=True, timeout=120)
    assert first.returncode == 0, first.stderr
    before = (out / "demos.hdf5").read_bytes()
    # An 450-step failed attempt, kept: its file is far larger than the limit; the index is not.
    events = tmp_path / "events.json"
    events.write_text(json.dumps([{"action": [0, 0, 0, 0]}] * 450 + [{"action": [0, 0, 0, 0], "finish": True}]))
    limit = 3 * len(before)
    second = subprocess.run(collector(out, "--device", "scripted", "--scripted-json", str(events),
                                      "--keep-failures"),
                            capture_output=True, text=True, timeout=120, preexec_fn=lambda: _limit_file_size(limit))
    assert second.returncode == 1
    assert "file-size limit" in second.stdout + second.stderr
    assert "saved before are intact" in second.stdout + second.stderr
    # The summary counts what is on disk: the failed save is not "saved" (it said "1 saved this session").
    assert "2 attempts, 0 saved this session (3 in" in second.stdout, second.stdout
    assert (out / "demos.hdf5").read_bytes() == before
    assert not list((out / "episodes").glob(".*.tmp")), "the partial file is removed"
    with open_dataset(out) as ds:
        assert ds.demo_names == ["demo_0", "demo_1", "demo_2"] and validate(ds) == []


@pytest.mark.parametrize("where", ["index", "episodes"])
def test_an_unwritable_output_is_a_clear_error(tmp_path: pathlib.Path, where: str) -> None:
    # A file where the directory should be is refused for every user (root ignores permissions, so
    # a chmod would prove nothing; the setup used to exist for root only, and as any other user the
    # test then collected happily and failed).
    target = tmp_path / "demos" if where == "index" else tmp_path / "demos" / "episodes"
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text("in the way")
    run = subprocess.run(collector(tmp_path / "demos", "--device", "expert", "--episodes", "1"),
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert "demos" in run.stderr and "error" in run.stderr
