"""Demo generation: subtask annotation, generated datasets that validate and replay exactly, the same
demos whatever the number of workers, resume after a SIGKILL, a dead worker replaced, provenance, bad input."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pathlib
import re
import signal
import subprocess
import sys
import threading
import time
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import fetch
from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.experts import make_expert
from fetch.generate import run
from fetch.generate.attempt import Generator, Options, Result, task_hand_response
from fetch.generate.room import CLEARANCE, FINGER_WIDTH, FINGERTIPS, pass_over
from fetch.generate.segments import Segment, annotate, from_frame, held_grip, to_frame
from fetch.generate.sources import load_sources
from fetch.generate.workers import RESTARTS, Work
from fetch.robot import ACTION_STEP, HAND_RESPONSE
from fetch.tasks import task_class
from fetch.tasks.subtasks import Frame

SIZE_KEYS = ("timestamps",)
"""Arrays that record wall-clock time, so differ between two runs that make the same demos."""
TIME_ATTRS = ("started", "ended")


def collect(env_id: str, out: pathlib.Path, episodes: int = 3) -> pathlib.Path:
    assert main(["collect", "--env", env_id, "--device", "expert", "--episodes", str(episodes), "--render", "none",
                 "--out", str(out)]) == 0
    return out


def gen_argv(source: pathlib.Path, out: pathlib.Path, demos: int, *more: str) -> list[str]:
    return ["generate", "--source", str(source), "--out", str(out), "--demos", str(demos), "--seed", "100", *more]


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Three PickPlace-v2 expert demos."""
    return collect("PickPlace-v2", tmp_path_factory.mktemp("src") / "pick")


@pytest.fixture(scope="module")
def serial(source: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Twelve demos generated in this process (one worker)."""
    out = tmp_path_factory.mktemp("gen") / "serial"
    assert main(gen_argv(source, out, 12, "--workers", "1")) == 0
    return out


def same_demos(a: pathlib.Path, b: pathlib.Path) -> None:
    """Every array and attribute equal, but wall-clock times."""
    with open_dataset(a) as x, open_dataset(b) as y:
        assert x.demo_names == y.demo_names
        assert x.masks() == y.masks()
        for name in x.demo_names:
            ax, ay = x.arrays(name), y.arrays(name)
            assert ax.keys() == ay.keys()
            for key in ax:
                if key not in SIZE_KEYS:
                    assert np.array_equal(ax[key], ay[key]), (name, key)
            tx = {k: v for k, v in x.attrs(name).items() if k not in TIME_ATTRS}
            ty = {k: v for k, v in y.attrs(name).items() if k not in TIME_ATTRS}
            assert tx == ty, name


# -- subtasks ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("env_id", fetch.ENV_IDS)
def test_every_task_declares_subtasks_its_expert_demos_complete(env_id: str) -> None:
    """Each task's subtasks end in order on an expert demo: every signal but the last fires."""
    subtasks = task_class(env_id).subtasks
    assert subtasks and subtasks[-1].done is None and all(s.done is not None for s in subtasks[:-1])
    env = gym.make(env_id, max_episode_steps=100)
    base = env.unwrapped
    expert = make_expert(env)
    seed = 0 if env_id != "Slide-v2" else 1  # a seed its expert solves
    obs, _ = env.reset(seed=seed)
    expert.reset()
    states = [base.get_state()]
    for _ in range(60):
        obs, _, _, _, _ = env.step(expert(obs))
        states.append(base.get_state())
    annotation = annotate(base, subtasks, np.array(states))
    assert annotation.complete, (env_id, annotation.bounds())
    labels = annotation.labels
    assert labels[0] == 0 and labels[-1] == len(subtasks) - 1
    assert np.all(np.diff(labels.astype(int)) >= 0)
    env.close()


def test_a_demo_that_never_grasps_is_not_complete() -> None:
    """The grasp signal needs the object between the fingers: a hand that only hovers never ends it."""
    env = gym.make("PickPlace-v2")
    base = env.unwrapped
    env.reset(seed=0)
    states = [base.get_state()]
    for _ in range(20):
        env.step(np.array([0.0, 0.0, 0.3, -1.0], np.float32))
        states.append(base.get_state())
    annotation = annotate(base, task_class("PickPlace-v2").subtasks, np.array(states))
    assert not annotation.complete and not annotation.labels.any()


def test_frames_carry_points_over_with_their_heading() -> None:
    """A point 10 cm ahead of a source frame lands 10 cm ahead of the new frame, along its heading;
    any point keeps its offset from the frame, turned by the change of heading."""
    src = Frame(np.array([1.0, 0.5, 0.4]), 0.0)
    new = Frame(np.array([1.3, 0.7, 0.45]), math.pi / 2)
    moved = from_frame(new, to_frame(src, np.array([[1.1, 0.5, 0.5]])))
    assert np.allclose(moved, [[1.3, 0.8, 0.55]])
    src, new = Frame(np.array([1.0, 0.5, 0.4]), 0.3), Frame(np.array([1.2, 0.9, 0.4]), 1.2)
    point = np.array([1.05, 0.62, 0.47])
    moved = from_frame(new, to_frame(src, point))
    c, s = math.cos(0.9), math.sin(0.9)
    d = point - src.pos
    assert np.allclose(moved - new.pos, [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]])
    assert np.allclose(to_frame(new, moved), to_frame(src, point))


def test_a_place_carried_over_to_a_lower_goal_does_not_press_the_hand_into_the_table() -> None:
    """A source that carried the block sideways, then up to a goal 25 cm above the table, carried over
    to a goal on the table: moved with the goal, its path starts 25 cm too low, and blending that offset
    out faster than the source rises would command the hand below the table for half the segment (the
    labels saying "press down" while the block drags). Up to the placement the path stays at or above
    the lower of its two ends; after it, the segment is the source's own."""
    table = 0.425
    held = np.array([1.30, 0.75, table + 0.03])  # the block lifted 3 cm
    sideways = [[1.30 + 0.02 * i, 0.75, table + 0.03] for i in range(1, 9)]
    up = [[1.46, 0.75, table + 0.03 + 0.0275 * i] for i in range(1, 9)]
    targets = np.array(sideways + up + [[1.46, 0.75, table + 0.25]] * 4)
    src_goal = Frame(np.array([1.46, 0.75, table + 0.25]), 0.0)
    segment = Segment("demo_0", 0, len(targets), held, targets, np.full(len(targets), -1.0), None, src_goal,
                      int(np.argmin(np.linalg.norm(targets - src_goal.pos, axis=1))))
    generator = Generator("PickPlace-v2", {}, [[segment] * 3], Options(max_steps=50), seed=0)
    try:
        new_goal = Frame(np.array([1.40, 0.70, table]), 0.0)
        path, grips, _, _ = generator.plan(segment, new_goal, np.array([1.25, 0.80, table + 0.03]))
    finally:
        generator.close()
    arrive = len(path) - (len(targets) - segment.closest)
    assert np.allclose(path[arrive], new_goal.pos)  # the placement itself is the source's
    assert path[:arrive, 2].min() >= table - 1e-12
    assert np.allclose(path[arrive:], from_frame(new_goal, to_frame(src_goal, targets[segment.closest:])))
    assert len(grips) == len(path)


# -- generation -------------------------------------------------------------------------------------

def test_generated_dataset_validates_replays_exactly_and_labels_its_steps(serial: pathlib.Path) -> None:
    assert main(["info", str(serial)]) == 0
    assert main(["replay", str(serial), "--check"]) == 0
    env = gym.make("PickPlace-v2").unwrapped
    subtasks = task_class("PickPlace-v2").subtasks
    with open_dataset(serial) as ds:
        assert len(ds.demo_names) == 12
        for name in ds.demo_names:
            arrays = ds.arrays(name)
            assert arrays["is_success"][-1] == 1
            recomputed = annotate(env, subtasks, arrays["states"], arrays["actions"][:, 3])
            assert np.array_equal(arrays["subtasks"], recomputed.labels)
            labels = arrays["subtasks"]
            # grasped, then (most often) lifted 2 cm and placed; a goal close above the table is
            # reached by a lift the noise kept under 2 cm
            assert labels[0] == 0 and np.all(np.diff(labels) >= 0) and 1 in labels and labels.max() <= 2


def test_generated_dataset_loads_in_robomimic_and_minari(serial: pathlib.Path, tmp_path: pathlib.Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    import minari

    from robomimic_rules import assert_robomimic_loadable

    assert_robomimic_loadable(serial / "demos.hdf5")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    assert main(["export", str(serial), "--to", "minari", "--dataset-id", "gen/pick-place/generated-v0"]) == 0
    loaded = minari.load_dataset("gen/pick-place/generated-v0")
    assert loaded.total_episodes == 12


def test_generated_demos_start_from_new_object_poses(source: pathlib.Path, serial: pathlib.Path) -> None:
    """Generation is not replay: every generated demo starts from a pose no source demo had."""
    with open_dataset(source) as src, open_dataset(serial) as gen:
        starts = [src.arrays(n)["obs/observation"][0, 3:6] for n in src.demo_names]
        for name in gen.demo_names:
            obj = gen.arrays(name)["obs/observation"][0, 3:6]
            assert min(np.linalg.norm(obj - s) for s in starts) > 1e-3


def test_provenance_names_real_source_segments(source: pathlib.Path, serial: pathlib.Path) -> None:
    env = gym.make("PickPlace-v2").unwrapped
    subtasks = task_class("PickPlace-v2").subtasks
    with open_dataset(source) as src:
        bounds = {n: annotate(env, subtasks, src.arrays(n)["states"]).bounds() for n in src.demo_names}
        fingerprint = None
    with open_dataset(serial) as ds:
        settings = ds.settings["generate"]
        assert settings["source"] == str((source / "demos.hdf5").resolve())
        assert settings["subtasks"] == ["grasp", "lift", "place"] and settings["source_demos"] == 3
        fingerprint = settings["source_fingerprint"]
        previous = -1
        for name in ds.demo_names:
            attrs = ds.attrs(name)
            demos, segments = json.loads(attrs["source_demos"]), json.loads(attrs["source_segments"])
            made = json.loads(attrs["source_subtasks"])
            assert len(demos) == len(segments) == len(made) >= 3 and made[0] == 0 and made[-1] == 2
            assert all(b == a + 1 or b <= a for a, b in zip(made, made[1:], strict=False))  # on, or made again
            assert sum(b <= a for a, b in zip(made, made[1:], strict=False)) <= 1  # --retries' default
            starts = json.loads(attrs["segment_starts"])
            assert len(starts) == len(made) and starts[0] == 0 and starts == sorted(starts) and starts[-1] < 50
            for k, demo, segment in zip(made, demos, segments, strict=True):
                assert tuple(segment) == bounds[demo][k]
            assert attrs["device"] == "generate" and attrs["seed"] == 100 + attrs["attempt"]
            assert attrs["generation_attempts"] == attrs["attempt"] - previous >= 1
            previous = attrs["attempt"]
    assert isinstance(fingerprint, str) and len(fingerprint) == 64


def test_same_demos_whatever_the_number_of_workers(source: pathlib.Path, serial: pathlib.Path,
                                                   tmp_path: pathlib.Path) -> None:
    out = tmp_path / "two"
    assert main(gen_argv(source, out, 12, "--workers", "2")) == 0
    same_demos(serial, out)


def test_running_again_when_complete_adds_nothing_and_more_continues(source: pathlib.Path, serial: pathlib.Path,
                                                                     tmp_path: pathlib.Path) -> None:
    """--demos is the size the dataset should reach: a first run of 5 then one of 12 equals one run of 12."""
    out = tmp_path / "grown"
    assert main(gen_argv(source, out, 5, "--workers", "1")) == 0
    assert main(gen_argv(source, out, 5, "--workers", "1")) == 0
    with open_dataset(out) as ds:
        assert len(ds.demo_names) == 5
    assert main(gen_argv(source, out, 12, "--workers", "1")) == 0
    same_demos(serial, out)


def test_resume_after_sigkill_gives_the_same_demos(source: pathlib.Path, serial: pathlib.Path,
                                                   tmp_path: pathlib.Path) -> None:
    out = tmp_path / "killed"
    argv = [sys.executable, "-m", "fetch.cli", *gen_argv(source, out, 12, "--workers", "1")]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    episodes = out / "episodes"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if episodes.is_dir() and len(list(episodes.glob("demo_*.hdf5"))) >= 3:
            break
        time.sleep(0.01)
    assert proc.poll() is None, "the run ended before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    with open_dataset(out) as ds:
        assert 0 < len(ds.demo_names) < 12
    assert main(gen_argv(source, out, 12, "--workers", "1")) == 0
    same_demos(serial, out)


class _Dying:
    """A worker's generator that, at attempt `at`, ends its own process (SIGKILL: a native crash, the
    out-of-memory killer) every time; or, with `marker`, only the first time any worker gets there, and
    then not by itself: it writes its pid to `marker` and waits for the test to kill it."""

    def __init__(self, inner: Generator, at: int, marker: str) -> None:
        self.inner, self.at, self.marker = inner, at, marker

    def attempt(self, number: int) -> Result:
        if number == self.at and not self.marker:
            os.kill(os.getpid(), signal.SIGKILL)
        if number == self.at:
            try:
                fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                pass  # killed once already: make it
            else:
                os.write(fd, f"{os.getpid()}\n".encode())
                os.close(fd)
                time.sleep(120)
        return self.inner.attempt(number)

    def close(self) -> None:
        self.inner.close()


@dataclasses.dataclass(frozen=True)
class _DyingWork(Work):
    """`Work` whose workers die at attempt `at` (`_Dying`); pickled by reference to this module."""

    at: int = 9
    marker: str = ""

    def generator(self) -> Any:
        return _Dying(super().generator(), self.at, self.marker)


def _children() -> dict[int, str]:
    """This process's child processes: pid -> command line."""
    found = {}
    for stat in pathlib.Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
            if ppid == os.getpid():
                found[int(stat.parent.name)] = (stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (OSError, IndexError, ValueError):
            continue
    return found


def _in_flight(err: str) -> list[int]:
    """The attempt that killed its worker (9), for each death `err` tells of, if the attempts it says were
    in flight hold it (which others were depends on timing)."""
    spans = [range(int(lo), int(hi) + 1) for lo, hi in re.findall(r"died \(SIGKILL\) with attempts (\d+)-(\d+)", err)]
    return [9 for span in spans if 9 in span]


@pytest.mark.skipif(not pathlib.Path("/proc/self/stat").exists(), reason="finds the pool's workers in /proc")
def test_a_worker_killed_mid_run_is_replaced_and_the_demos_are_the_same(
        source: pathlib.Path, serial: pathlib.Path, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker SIGKILLed (`kill -9`, the out-of-memory killer) while it makes attempt 9 broke the pool and
    ended the run with a BrokenProcessPool traceback. New workers make the attempts in flight again: the
    run ends as an uninterrupted one, with the same demos."""
    marker = tmp_path / "stalled-pid"
    monkeypatch.setattr(run, "Work", lambda *a: _DyingWork(*a, marker=str(marker)))
    killed: list[int] = []

    def kill_the_stalled_worker() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            text = marker.read_text() if marker.exists() else ""
            if text.endswith("\n"):
                pid = int(text)
                assert "spawn_main" in _children().get(pid, ""), "not a worker of this process's pool"
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
            time.sleep(0.01)

    killer = threading.Thread(target=kill_the_stalled_worker, daemon=True)
    killer.start()
    out = tmp_path / "replaced"
    assert main(gen_argv(source, out, 12, "--workers", "2")) == 0
    killer.join(timeout=5)
    assert killed, "no worker was killed"
    err = capsys.readouterr().err
    assert "starting new workers" in err and _in_flight(err) == [9], err
    assert "Traceback" not in err
    assert not [pid for pid, line in _children().items() if "spawn_main" in line], "workers left behind"
    same_demos(serial, out)


def test_a_worker_that_dies_every_time_ends_the_run_with_one_line_and_the_demos_saved(
        source: pathlib.Path, serial: pathlib.Path, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A death that comes back (attempt 9 crashes its worker every time) stops the run after `RESTARTS`
    new pools, with one line and exit status 2; the demos saved before stay valid and the same command,
    run again (here without the crash), ends with the demos an uninterrupted run makes."""
    monkeypatch.setattr(run, "Work", _DyingWork)
    out = tmp_path / "dying"
    assert main(gen_argv(source, out, 12, "--workers", "2")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len([line for line in err if "starting new workers" in line]) == RESTARTS
    assert "error: a generate worker died (SIGKILL)" in err[-1] and _in_flight("\n".join(err)) == [9] * 3, err
    assert f"after {RESTARTS} restarts" in err[-1] and "run the same command again" in err[-1]
    assert not [pid for pid, line in _children().items() if "spawn_main" in line], "workers left behind"
    assert main(["info", str(out)]) == 0
    with open_dataset(out) as ds:
        assert all(int(ds.attrs(n)["attempt"]) < 8 for n in ds.demo_names)
    monkeypatch.undo()
    assert main(gen_argv(source, out, 12, "--workers", "2")) == 0
    same_demos(serial, out)


def test_demos_run_to_the_horizon_and_end_in_success_unless_told_to_stop(
        source: pathlib.Path, serial: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """By default every generated demo runs the env's 50 steps, like the collector's expert demos, and
    is kept only if success holds over its last 5; with --stop-on-success it ends where success had
    held 5 steps (MimicGen's demos), so earlier."""
    with open_dataset(serial) as ds:
        assert ds.settings["stop_on_success"] is False
        for name in ds.demo_names:
            success = ds.arrays(name)["is_success"]
            assert len(success) == 50, name
            assert success[-5:].all(), name
    stopped = tmp_path / "stopped"
    assert main(gen_argv(source, stopped, 4, "--workers", "1", "--stop-on-success")) == 0
    with open_dataset(stopped) as ds:
        assert ds.settings["stop_on_success"] is True
        for name in ds.demo_names:
            success = ds.arrays(name)["is_success"]
            assert len(success) < 50, name
            assert success[-5:].all() and not success[:-5].all(), name


def test_resume_with_other_settings_is_refused(source: pathlib.Path, serial: pathlib.Path,
                                               tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "other"
    assert main(gen_argv(source, out, 2, "--workers", "1")) == 0
    assert main(gen_argv(source, out, 4, "--workers", "1", "--noise", "0.05")) == 2
    err = capsys.readouterr().err
    assert "recorded differently" in err  # and names the one setting that differs, not every one
    assert "settings.generate.noise: the dataset has 0.1, this session 0.05" in err and "transit_speed" not in err


def test_options_added_later_are_recorded_only_when_on(source: pathlib.Path, serial: pathlib.Path,
                                                       tmp_path: pathlib.Path) -> None:
    """`--retries 0 --no-fit-opening --no-steady-fit` records the settings as generate did before those options
    existed (so such a dataset resumes with them), as does a `--finger-noise` equal to `--noise` (the default),
    `--starts all` and `--hand-response 1` (the defaults); the defaults record the three, and another finger noise
    or hand response records that too."""
    later = {"retries", "fit_opening", "steady_fit"}
    with open_dataset(serial) as ds:
        recorded = ds.settings["generate"]
        assert recorded["retries"] == 1 and recorded["fit_opening"] is True and recorded["steady_fit"] is True
        assert "finger_noise" not in recorded and "starts" not in recorded and "hand_response" not in recorded
    before = tmp_path / "before"
    assert main(gen_argv(source, before, 2, "--workers", "1", "--retries", "0", "--no-fit-opening",
                         "--no-steady-fit", "--finger-noise", "0.1")) == 0
    with open_dataset(before) as ds:
        assert set(ds.settings["generate"]) == set(recorded) - later
    metres = tmp_path / "metres"
    assert main(gen_argv(source, metres, 2, "--workers", "1", "--finger-noise", "0.005")) == 0
    with open_dataset(metres) as ds:
        assert ds.settings["generate"]["finger_noise"] == 0.005
    following = tmp_path / "following"
    assert main(gen_argv(source, following, 2, "--workers", "1", "--hand-response", str(HAND_RESPONSE))) == 0
    with open_dataset(following) as ds:
        assert ds.settings["generate"]["hand_response"] == HAND_RESPONSE


def test_tight_starts_on_a_task_without_any_is_one_error(source: pathlib.Path, tmp_path: pathlib.Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """PickPlace's block never stands beside anything: `--starts tight` says so in one line, naming the choice
    that works, rather than skipping starts for ever."""
    assert main(gen_argv(source, tmp_path / "tight", 2, "--workers", "1", "--starts", "tight")) == 2
    err = capsys.readouterr().err.strip()
    assert "PickPlace-v2 is tight" in err and "use --starts all" in err and len(err.splitlines()) == 1


def test_a_missed_grasp_is_made_again_from_where_the_hand_is(source: pathlib.Path) -> None:
    """With noise that makes grasps miss, --retries makes the grasp again: the attempt is the same as without
    retries up to the first retry, which begins where the object is not held, and some attempts that fail
    without retries succeed with them."""
    sources = load_sources(source)
    plain, again = (Generator(sources.env_id, sources.env_kwargs, sources.segments,
                              Options(max_steps=50, noise=0.3, retries=retries), 100) for retries in (0, 2))
    recovered = retried = 0
    try:
        for number in range(100):
            r0, r1 = plain.attempt(number), again.attempt(number)
            assert [c[3] for c in r0.choices] == list(range(len(r0.choices)))
            made = [c[3] for c in r1.choices]
            back = [i for i in range(1, len(made)) if made[i] <= made[i - 1]]
            assert len(back) <= 2 and all(made[i] == 0 for i in back)  # only the grasp is made again
            if not back:
                assert r1.choices == r0.choices and r1.success == r0.success and r1.steps == r0.steps
                continue
            retried += 1
            assert r1.choices[:back[0]] == r0.choices[:back[0]]
            recovered += r1.success and not r0.success
            if r1.demo is not None:  # each retry began with the object out of the fingers
                states = r1.demo.arrays["states"]
                for i in back:
                    again.base.set_state(states[r1.starts[i]])
                    assert again.scene.touching(again.base.data, "object0") != (True, True)
    finally:
        plain.close()
        again.close()
    assert retried >= 3 and recovered >= 1, (retried, recovered)


def test_a_drawer_task_generates_too(tmp_path: pathlib.Path) -> None:
    src = collect("Drawer-open-v2", tmp_path / "src", episodes=2)
    out = tmp_path / "gen"
    assert main(["generate", "--source", str(src), "--out", str(out), "--demos", "4", "--workers", "1"]) == 0
    assert main(["replay", str(out), "--check"]) == 0
    with open_dataset(out) as ds:
        assert all(set(ds.arrays(n)["subtasks"].tolist()) == {0, 1} for n in ds.demo_names)


@pytest.mark.parametrize("env_id", ["PickPlace-v2", "Drawer-close-v2"])
def test_the_hand_covers_hand_response_of_a_commanded_step(env_id: str) -> None:
    """`HAND_RESPONSE` is what the physics does: moving freely along any axis, either way, slow or fast, the hand
    covers that share of each commanded step once moving (the first step from rest a little less). Upwards only
    along z: downwards the hand soon meets the table, or Drawer-close's cabinet under it."""
    env = gym.make(env_id)
    try:
        for axis in range(3):
            for a in (-1.0, -0.3, 0.3, 1.0) if axis < 2 else (0.3, 1.0):
                env.reset(seed=3)
                action = np.zeros(4, np.float32)
                action[axis], action[3] = a, 1.0
                shares = []
                for _ in range(3):
                    before = held_grip(env.unwrapped).copy()
                    env.step(action)
                    shares.append((held_grip(env.unwrapped) - before)[axis] / (ACTION_STEP * a))
                assert 0.55 <= shares[0] < HAND_RESPONSE, (axis, a, shares)
                assert np.allclose(shares[1:], HAND_RESPONSE, atol=0.025), (axis, a, shares)
    finally:
        env.close()


def test_drawer_close_follows_the_path_unless_told_and_other_tasks_do_not(tmp_path: pathlib.Path) -> None:
    """`--hand-response` unset is the task's: Drawer-close's datasets record `HAND_RESPONSE`, other tasks' record
    nothing (1, as before the option), and a number given is what is recorded."""
    src = collect("Drawer-close-v2", tmp_path / "src", episodes=2)
    for more, recorded in (([], HAND_RESPONSE), (["--hand-response", "1"], None)):
        out = tmp_path / f"gen{len(more)}"
        assert main(["generate", "--source", str(src), "--out", str(out), "--demos", "2", "--workers", "1",
                     *more]) == 0
        with open_dataset(out) as ds:
            assert ds.settings["generate"].get("hand_response") == recorded
    assert task_hand_response("PickPlace-v2") == 1.0


def test_with_the_hands_response_a_step_gets_to_its_target(source: pathlib.Path) -> None:
    """A step towards a point 3 cm off gets within 4 mm of it when generate takes the hand's response into account
    (`Options.hand_response`), and stops over a centimetre short when it takes the hand to go where it is told."""
    sources = load_sources(source)
    short = {}
    for response in (1.0, HAND_RESPONSE):
        gen = Generator(sources.env_id, sources.env_kwargs, sources.segments,
                        Options(max_steps=50, noise=0.0, hand_response=response), 0)
        try:
            obs, _ = gen.env.reset(seed=3)
            gen.buffer.begin(obs, gen.base.get_state())
            target = held_grip(gen.base) + np.array([0.03, 0.0, 0.0])
            gen._step(target, 1.0, None, np.random.default_rng(0), 0)
            short[response] = float(np.linalg.norm(target - held_grip(gen.base)))
        finally:
            gen.close()
    assert short[HAND_RESPONSE] < 0.004 < 0.01 < short[1.0], short


def test_following_the_path_brings_the_fingers_down_in_the_drawers_slot(tmp_path: pathlib.Path) -> None:
    """Drawer-close's demos hook the fingers into the 4 cm slot behind the handle. Commanding the path as if the
    hand got all the way, the hand trails it by 1-1.5 cm and, in a share of the demos, comes down on the drawer's
    front and never into the slot (the drawer dragged shut by friction); with the hand's response taken into
    account (nearly) every demo's fingers go into it."""
    src = collect("Drawer-close-v2", tmp_path / "src", episodes=3)
    sources = load_sources(src)
    env = gym.make("Drawer-close-v2")
    grip_pos = env.unwrapped.observation_layout["grip_pos"]
    env.close()
    never = {}
    for response in (1.0, HAND_RESPONSE):
        gen = Generator(sources.env_id, sources.env_kwargs, sources.segments,
                        Options(max_steps=50, hand_response=response), 100)
        try:
            demos = [d for d in (gen.attempt(number).demo for number in range(30)) if d is not None]
        finally:
            gen.close()
        # the fingertips below the top of the drawer's front: in the slot (or in front of the handle)
        never[response] = sum(not (d.arrays["obs/observation"][:, grip_pos][:, 2] < 0.51).any() for d in demos)
        assert len(demos) >= 20, (response, len(demos))
    assert never[HAND_RESPONSE] <= 2 and never[1.0] >= 5, never


# -- bad input --------------------------------------------------------------------------------------

@pytest.mark.parametrize(("more", "message"), [
    (["--selection", "closest"], "unknown selection 'closest'"),
    (["--workers", "0"], "--workers must be at least 1"),
    (["--noise", "-1"], "--noise must be a finite standard deviation"),
    (["--finger-noise", "nan"], "--finger-noise must be a finite standard deviation"),
    (["--max-steps", "0"], "--max-steps must be at least 1"),
    (["--hand-response", "0"], "--hand-response must be a number from 0.1 to 1"),
])
def test_bad_arguments_are_named(source: pathlib.Path, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
                                 more: list[str], message: str) -> None:
    assert main(gen_argv(source, tmp_path / "x", 2, *more)) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_demos_must_be_positive(source: pathlib.Path, tmp_path: pathlib.Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    assert main(gen_argv(source, tmp_path / "x", 0)) == 2
    assert "--demos must be at least 1" in capsys.readouterr().err


def test_a_source_without_usable_demos_is_refused(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Failed demos only (kept with --keep-failures): nothing to cut into segments."""
    src = tmp_path / "failed"
    assert main(["collect", "--env", "PickPlace-v2", "--device", "scripted", "--episodes", "1", "--max-steps", "3",
                 "--keep-failures", "--render", "none", "--out", str(src)]) == 0
    assert main(gen_argv(src, tmp_path / "x", 2)) == 2
    assert "none of its 1 demos is a success" in capsys.readouterr().err


def test_gives_up_after_max_attempts(source: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """No attempt can succeed in 3 steps: the run stops at --max-attempts with a non-zero exit."""
    assert main(gen_argv(source, tmp_path / "x", 2, "--workers", "1", "--max-steps", "3", "--max-attempts", "5")) == 1


def test_a_run_where_few_attempts_succeed_says_so_early(source: pathlib.Path, tmp_path: pathlib.Path,
                                                        capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """After `LOW_YIELD` attempts at a rate below it, generate says what to expect instead of running on
    silently (Slide: 20 minutes for 855 of 1000 demos)."""
    from fetch.generate import run

    monkeypatch.setattr(run, "LOW_YIELD", (5, 0.05))
    assert main(gen_argv(source, tmp_path / "x", 2, "--workers", "1", "--max-steps", "3", "--max-attempts", "8")) == 1
    err = capsys.readouterr().err
    assert "only 0 of 5 attempts succeeded (0.0 %): at this rate --max-attempts (8) runs out with about 0 of " \
           "the 2 demos" in err


def test_the_low_yield_note_estimates_the_time_left_and_is_quiet_at_a_good_rate() -> None:
    from fetch.generate.run import Summary, low_yield

    few = Summary(saved=6, total=6, attempts=200, successes=6, seconds=0.0, workers=2, out="x")
    note = low_yield(few, wanted=100, limit=5000, seconds=60.0)  # 94 more at 3 %: ~3133 attempts, 15.7 min
    assert note is not None and "only 6 of 200 attempts succeeded (3.0 %)" in note
    assert "the other 94 demos take ~16 min" in note
    fine = Summary(saved=20, total=20, attempts=200, successes=20, seconds=0.0, workers=2, out="x")
    assert low_yield(fine, wanted=100, limit=5000, seconds=60.0) is None


def test_subtasks_command_prints_each_demos_segments(source: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["subtasks", str(source)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "PickPlace-v2: subtasks grasp, lift, place"
    env = gym.make("PickPlace-v2").unwrapped
    with open_dataset(source) as ds:
        for line, name in zip(lines[1:], ds.demo_names, strict=True):
            (g0, g1), (l0, l1), (p0, p1) = annotate(env, task_class("PickPlace-v2").subtasks,
                                                    ds.arrays(name)["states"]).bounds()
            assert line == f"{name}: grasp {g0}-{g1 - 1}, lift {l0}-{l1 - 1}, place {p0}-{p1 - 1}"
            assert g0 == 0 and l0 == g1 and p0 == l1 and 0 < g1 < l1 < p1


def test_a_source_that_stopped_short_of_the_goal_is_carried_the_rest_of_the_way() -> None:
    """A person stops once success shows, the object at the edge of the 5 cm region: a last segment
    with `settle` ends that much further, the correction growing from the start to the closest approach."""
    table = 0.425
    held = np.array([1.30, 0.75, table + 0.05])
    targets = np.array([[1.30 + 0.02 * i, 0.75, table + 0.05] for i in range(1, 9)])
    goal = Frame(np.array([1.50, 0.75, table + 0.05]), 0.0)
    closest = int(np.argmin(np.linalg.norm(targets - goal.pos, axis=1)))
    plain = Segment("demo_0", 0, len(targets), held, targets, np.full(len(targets), -1.0), None, goal, closest)
    settled = dataclasses.replace(plain, settle=np.array([0.04, 0.0, 0.0]))
    generator = Generator("PickPlace-v2", {}, [[plain] * 3], Options(max_steps=50), seed=0)
    try:
        new_goal = Frame(np.array([1.40, 0.70, table + 0.05]), 0.0)
        a = generator.plan(plain, new_goal, held).path
        b = generator.plan(settled, new_goal, held).path
    finally:
        generator.close()
    assert np.allclose(b[-1] - a[-1], [0.04, 0.0, 0.0])
    assert np.all(np.diff((b - a)[:, 0]) >= -1e-12) and (b - a)[0, 0] <= 0.04 / (closest + 1) + 1e-12


def test_a_drawer_pushed_short_of_its_goal_is_pushed_the_rest_of_the_way_over_the_whole_segment() -> None:
    """A segment anchored on what the hand moves (a drawer's handle, hooked) closes its source's gap by its
    last step (`settle_by`), growing step by step from the first: its closest approach to its own
    anchor is where it starts, and closing the gap there would jerk the hooked hand."""
    table = 0.425
    held = np.array([1.30, 0.75, table + 0.05])
    targets = np.array([[1.30 - 0.02 * i, 0.75, table + 0.05] for i in range(1, 9)])
    handle = Frame(held.copy(), 0.0)
    plain = Segment("demo_0", 0, len(targets), held, targets, np.full(len(targets), -1.0), None, handle, 0)
    settled = dataclasses.replace(plain, settle=np.array([-0.04, 0.0, 0.0]), settle_by=len(targets) - 1)
    generator = Generator("Drawer-close-v2", {}, [[plain] * 2], Options(max_steps=50), seed=0)
    try:
        a = generator.plan(plain, handle, held).path
        b = generator.plan(settled, handle, held).path
    finally:
        generator.close()
    shift = (b - a)[:, 0]
    assert np.allclose(shift, -0.04 * np.arange(1, 9) / 8)


def test_a_drawer_is_pushed_to_the_attempts_goal_not_to_where_the_sources_would_be() -> None:
    """A last segment anchored on a hooked handle starts relative to the handle and ends relative to the
    goal (`Segment.goal`): where the hook pulled the drawer 3 cm further open than in the source, the
    push goes 3 cm further, the shift growing over the segment."""
    table = 0.425
    held = np.array([1.20, 0.75, table + 0.1])
    targets = np.array([[1.20 + 0.02 * i, 0.75, table + 0.1] for i in range(1, 9)])
    handle = Frame(held.copy(), 0.0)
    plain = Segment("demo_0", 0, len(targets), held, targets, np.full(len(targets), -1.0), None, handle, 0,
                    settle_by=len(targets) - 1)
    generator = Generator("Drawer-close-v2", {}, [[plain] * 2], Options(max_steps=50), seed=0)
    try:
        generator.attempt(0)  # an observation to take the goal from
        goal = generator._obs["desired_goal"].copy()
        at_goal = dataclasses.replace(plain, goal=to_frame(handle, goal))  # the source's goal where ours is
        short = dataclasses.replace(plain, goal=to_frame(handle, goal - [0.03, 0.0, 0.0]))
        a = generator.plan(plain, handle, held).path
        b = generator.plan(at_goal, handle, held).path
        c = generator.plan(short, handle, held).path
    finally:
        generator.close()
    assert np.allclose(a, b)
    assert np.allclose((c - a)[:, 0], 0.03 * np.arange(1, 9) / 8) and np.allclose((c - a)[:, 1:], 0.0)


def test_a_pass_over_a_loose_object_is_lifted_clear_of_it_and_a_descent_onto_it_is_not() -> None:
    """`pass_over`: a hand that crosses a block low (a person going over it with a centimetre to spare)
    is lifted so that its fingertips clear it; a path that ends over it (coming down to grasp) and one
    that never crosses it are left as they are."""
    block = np.array([1.30, 0.75, 0.425])
    radius, height = 0.0354, 0.025
    top = block[2] + height + FINGERTIPS + CLEARANCE
    crossing = np.array([[1.42 - 0.02 * i, 0.75, 0.425 + 0.035] for i in range(12)])  # 1.42 .. 1.20
    lifted = crossing.copy()
    pass_over(lifted, block, radius, height)
    over = np.abs(crossing[:, 0] - block[0]) < radius + FINGER_WIDTH
    assert over.any() and np.allclose(lifted[over, 2], top)
    assert np.all(lifted[:, 2] >= crossing[:, 2]) and np.allclose(lifted[:, :2], crossing[:, :2])
    assert np.allclose(lifted[[0, -1], 2], crossing[[0, -1], 2])  # away from the block: as it was
    descent = np.array([[1.30, 0.75, 0.425 + 0.15 - 0.015 * i] for i in range(10)])
    grasp = descent.copy()
    pass_over(grasp, block, radius, height)
    assert np.array_equal(grasp, descent)
    beside = crossing + [0.0, 0.12, 0.0]
    kept = beside.copy()
    pass_over(kept, block, radius, height)
    assert np.array_equal(kept, beside)


def _drive(env_id: str, seed: int, waypoints: list[tuple[str, np.ndarray, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Saved states and actions of an episode that moves the hand to each waypoint in turn (relative to the
    object at that moment when the first element is "object"), fingers closed, `n` steps each."""
    env = gym.make(env_id)
    base = env.unwrapped
    obs, _ = env.reset(seed=seed)
    layout = base.observation_layout
    states, actions = [base.get_state()], []
    for anchor, offset, steps in waypoints:
        for _ in range(steps):
            grip, obj = obs["observation"][layout["grip_pos"]], obs["observation"][layout["object_pos"]]
            target = (obj if anchor == "object" else grip) + offset
            action = np.append(np.clip((target - grip) / 0.05, -1, 1), -1.0).astype(np.float32)
            obs, *_ = env.step(action)
            states.append(base.get_state())
            actions.append(action)
    env.close()
    return np.array(states), np.array(actions)


def test_an_approach_done_again_ends_where_the_hand_came_down_the_last_time() -> None:
    """A person's hand reached the place beside the block, found it off the line, went up and came down
    again before pushing: the approach subtask ends with the last coming down (`_redone`), so the push
    segment is a push, not a climb, a shift and a descent replayed wherever the block then is."""
    behind = np.array([-0.06, 0.0, 0.0])  # the push's start (+x: the push direction in these waypoints)
    states, _ = _drive("Push-v2", 3, [("object", behind + [0, 0, 0.08], 25), ("object", behind, 15),
                                            ("object", behind + [0, 0.04, 0.08], 12),
                                            ("object", behind, 15), ("object", [0.02, 0, 0], 12)])
    base = gym.make("Push-v2").unwrapped
    subtasks = task_class("Push-v2").subtasks
    labels = annotate(base, subtasks, states).labels
    first_down, up_again = 25, 40
    approach_end = int(np.flatnonzero(labels == 0)[-1])
    assert approach_end > up_again + 12, "the approach ends with the second coming down"
    # Without the redo (the signal held once, and never lost before the push), the boundary stays where it fired.
    states2, _ = _drive("Push-v2", 3, [("object", behind + [0, 0, 0.08], 25), ("object", behind, 15),
                                       ("object", [0.02, 0, 0], 12)])
    labels2 = annotate(base, subtasks, states2).labels
    assert first_down < int(np.flatnonzero(labels2 == 0)[-1]) < up_again
