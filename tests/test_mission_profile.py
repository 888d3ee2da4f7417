"""`benchmarks/mission_profile.py`'s reading of a py-spy profile: which process and thread a sample is of, and
which category it goes to, on lines shaped as py-spy 0.4 writes them (`record --threads -f raw`)."""

from __future__ import annotations

import importlib
import pathlib
from collections.abc import Callable
from typing import Any

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent

MAIN = 'process 10:"python -m fetch.cli generate --out a;b"'
"""The parent; its command line holds a ';', as a spawned worker's always does."""
WORKER = 'process 11:"python -B -c from multiprocessing.spawn import spawn_main; spawn_main(tracker_fd=9)"'
TRACKER = 'process 12:"python -B -c from multiprocessing.resource_tracker import main;main(8)"'


def _line(*frames: str, count: int) -> str:
    return ";".join(frames) + f" {count}"


@pytest.fixture
def classify(monkeypatch: pytest.MonkeyPatch) -> Callable[..., Any]:
    """The script's `classify`, imported from this checkout's benchmarks folder."""
    monkeypatch.syspath_prepend(str(ROOT))
    return importlib.import_module("benchmarks.mission_profile").classify  # type: ignore[no-any-return]


def test_samples_go_to_their_process_s_first_matching_category(classify: Callable[..., Any],
                                                                tmp_path: pathlib.Path) -> None:
    raw = tmp_path / "generate.txt"
    raw.write_text("\n".join([
        # a worker rendering a demo's images, and stepping the physics
        _line(MAIN, WORKER, "thread (11): MainThread", "_run_chunk (fetch/generate/workers.py:109)",
              "Generator.attempt (fetch/generate/attempt.py:325)", "Generator.render (fetch/generate/attempt.py:344)",
              count=30),
        _line(MAIN, WORKER, "thread (11): MainThread", "Generator.attempt (fetch/generate/attempt.py:300)",
              "Robot.advance (fetch/robot.py:231)", count=10),
        # a worker's Python with no category of its own, and one of its other threads
        _line(MAIN, WORKER, "thread (11): MainThread", "Generator.plan (fetch/generate/attempt.py:210)", count=5),
        _line(MAIN, WORKER, "thread (13): QueueFeederThread", "Thread._bootstrap (threading.py:1002)", count=99),
        # the resource tracker, a child that waits out the run, and the parent writing
        _line(MAIN, TRACKER, "thread (12): MainThread", "main (multiprocessing/resource_tracker.py:227)", count=500),
        _line(MAIN, "thread (10): MainThread", "DatasetWriter.close (fetch/dataset/writer.py:373)", count=7),
    ]) + "\n")
    assert classify(raw, "generate", workers=True) == {"rendering the images (EGL)": 30, "physics (mj_step)": 10,
                                                       "planning, the expert, the rest (Python)": 5}
    assert classify(raw, "generate", workers=False) == {"reading the source demos": 7}


def test_a_training_step_splits_into_its_parts(classify: Callable[..., Any], tmp_path: pathlib.Path) -> None:
    raw = tmp_path / "train.txt"
    loop = "loop (fetch/learn/train.py:280)"
    raw.write_text("\n".join([
        _line(MAIN, "thread (10): MainThread", loop, "pixel_loss (fetch/learn/pixels.py:133)",
              "PixelChunk.features (fetch/learn/pixels.py:105)", "random_shift (fetch/learn/pixels.py:78)", count=4),
        _line(MAIN, "thread (10): MainThread", loop, "pixel_loss (fetch/learn/pixels.py:133)",
              "Conv2d.forward (torch/nn/modules/conv.py:548)", count=20),
        _line(MAIN, "thread (10): MainThread", loop, "Tensor.backward (torch/_tensor.py:630)", count=40),
        _line(MAIN, "thread (10): MainThread", loop, "Adam.step (torch/optim/adam.py:240)", count=3),
        _line(MAIN, "thread (10): MainThread", "_find_and_load (<frozen importlib._bootstrap>:1176)", count=9),
    ]) + "\n")
    assert classify(raw, "train", workers=False) == {"batches: indexing, random shift": 4, "forward and loss": 20,
                                                     "backward": 40, "optimizer (AdamW)": 3, "start-up: imports": 9}
