"""What a newcomer trips on: the scripted device's format and built-in pattern, no pad and no display, no OSMesa."""

from __future__ import annotations

import glob
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.teleop.scripted import _EVENT_KEYS, SCRIPT_FORMAT

# ---- --device scripted ----


def test_scripted_without_a_file_says_it_runs_the_builtin_pattern(tmp_path: pathlib.Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    # the seed's own test command, which used to discard, quit and exit 0 without a word
    code = main(["collect", "--env", "Reach-v2", "--device", "scripted", "--episodes", "1", "--max-steps", "20",
                 "--render", "none", "--out", str(tmp_path / "out")])
    out, err = capsys.readouterr()
    assert code == 0
    notices = [line for line in err.splitlines() if line.startswith("no --scripted-json: running the built-in "
                                                                     "test pattern")]
    assert len(notices) == 1 and "which saves nothing" in notices[0], err
    assert "scripted: next attempt starts at event 0 (of 0..10)" in out
    assert "attempt 0 (seed 0): 10 steps, ended by discard, not saved" in out
    assert "scripted: all 11 events used; quitting" in out


def test_one_event_list_spans_the_attempts_with_the_documented_semantics(tmp_path: pathlib.Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    idle = {"action": [0, 0, 0, 0]}
    events = ([idle] * 3 + [{"action": [1, 1, 1, 1], "discard": True}]  # 0-3: discard, its action not stepped
              + [idle] * 4  # 4-7: the whole of an attempt cut by --max-steps 4; the list runs on
              + [idle, {"action": [0, 0, 0, -1], "finish": True}]  # 8-9: finish steps, then ends
              + [{"action": [1, 0, 0, 0], "quit": True}, idle])  # 10: quit without stepping; 11 never read
    script = tmp_path / "events.json"
    script.write_text(json.dumps(events))
    out_dir = tmp_path / "out"
    code = main(["collect", "--env", "Reach-v2", "--device", "scripted", "--scripted-json", str(script),
                 "--max-steps", "4", "--keep-failures", "--verbose", "--render", "none", "--out", str(out_dir)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert f"scripted: 12 events from {script}" in err
    lines = [line for line in out.splitlines() if line.startswith(("scripted:", "attempt"))]
    assert lines == [
        "scripted: next attempt starts at event 0 (of 0..11)",
        "attempt 0 (seed 0): 3 steps, ended by discard, not saved",
        "scripted: next attempt starts at event 4 (of 0..11)",
        "attempt 1 (seed 1): 4 steps, ended by time limit",
        "scripted: next attempt starts at event 8 (of 0..11)",
        "attempt 2 (seed 2): 2 steps, ended by finish",
        "scripted: next attempt starts at event 10 (of 0..11)",
        "attempt 3 (seed 3): 0 steps, ended by quit, not saved",
    ], out
    with open_dataset(out_dir) as ds:
        assert [int(ds.demo(n).attrs["attempt"]) for n in ds.demo_names] == [1, 2]
        assert int(ds.demo("demo_1").attrs["num_samples"]) == 2
        np.testing.assert_array_equal(ds.demo("demo_1")["actions"][-1], [0, 0, 0, -1])


def test_script_flags_must_be_booleans_and_every_key_is_documented(tmp_path: pathlib.Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    script = tmp_path / "events.json"
    script.write_text(json.dumps([{"action": [0, 0, 0, 0]}, {"quit": "no"}]))
    code = main(["collect", "--env", "Reach-v2", "--device", "scripted", "--scripted-json", str(script),
                 "--render", "none", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and f"{script}: event 1: \"quit\" must be true or false, got 'no'" in err
    for key in _EVENT_KEYS:
        assert f'"{key}"' in SCRIPT_FORMAT, key


# ---- no pad, no display ----


def _headless_env(**extra: str) -> dict[str, str]:
    """This environment without a display, and without the GL choice `import fetch` made in this process."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "XDG_RUNTIME_DIR",
                                                           "SDL_VIDEODRIVER", "MUJOCO_GL", "PYOPENGL_PLATFORM")}
    env.update(extra)
    return env


@pytest.mark.skipif(sys.platform != "linux", reason="DISPLAY and SDL's video drivers: Linux")
@pytest.mark.skipif(bool(glob.glob("/dev/input/js*")), reason="a joystick is plugged into this machine")
@pytest.mark.parametrize("driver", [None, "dummy"])
def test_no_pad_and_no_display_is_one_message_naming_the_headless_devices(tmp_path: pathlib.Path,
                                                                         driver: str | None) -> None:
    env = _headless_env(**({"SDL_VIDEODRIVER": driver} if driver else {}))
    run = subprocess.run([sys.executable, "-m", "fetch.collect", "--render", "none", "--out", str(tmp_path / "out")],
                         capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path)
    assert run.returncode == 2 and run.stdout == "", (run.stdout, run.stderr)
    lines = run.stderr.splitlines()
    assert len(lines) == 1, run.stderr  # nothing before it: no "XDG_RUNTIME_DIR is invalid or not set"
    assert lines[0].startswith("gym-fetch collect: error: no gamepad found, and no display")
    for words in ("--device expert", "--device scripted", "--device keyboard needs a display"):
        assert words in lines[0]
    assert "gym-fetch gamepad" not in lines[0]  # no pad at all is not a pad to test
    assert not (tmp_path / "out").exists()


# ---- MUJOCO_GL=osmesa without OSMesa ----

HIDE_OSMESA = """
import ctypes
_load = ctypes.CDLL.__init__
def _without_osmesa(self, name, *args, **kwargs):
    if name and "OSMesa" in str(name):
        raise OSError(f"{name}: cannot open shared object file: No such file or directory")
    _load(self, name, *args, **kwargs)
ctypes.CDLL.__init__ = _without_osmesa
"""
"""Makes the dynamic loader miss libOSMesa, where PyOpenGL and we load it, on a machine that has it
(this one has not: there the subprocess meets the real failure)."""


def _python(code: str, cwd: pathlib.Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", HIDE_OSMESA + code], capture_output=True, text=True,
                          timeout=300, env=_headless_env(MUJOCO_GL="osmesa"), cwd=cwd)


def test_osmesa_missing_fails_at_render_with_one_line_naming_the_package(tmp_path: pathlib.Path) -> None:
    run = _python("""
import os
import gymnasium as gym
import fetch
env = gym.make("Reach-v2", render_mode="rgb_array")
env.reset(seed=0)
env.step(env.action_space.sample())  # what does not render works
print(os.environ["MUJOCO_GL"])
try:
    env.render()
except fetch.FetchError as e:
    print(e)
    raise SystemExit(3)
""", tmp_path)
    assert run.returncode == 3, run.stderr
    assert "glGetError" not in run.stderr and "Traceback" not in run.stderr
    backend, message = run.stdout.splitlines()
    assert backend == "osmesa"  # the user's choice is left as it was
    assert message.startswith("MUJOCO_GL=osmesa needs the OSMesa library")
    assert "apt-get install libosmesa6" in message and "MUJOCO_GL=egl" in message


def test_osmesa_missing_collects_headless_and_the_cli_says_it_in_one_line(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "out"
    cli = "from fetch.cli import main\nraise SystemExit(main({}))\n"
    collect = _python(cli.format(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "1",
                                  "--render", "none", "--out", str(out)]), tmp_path)
    assert collect.returncode == 0, collect.stderr
    video = _python(cli.format(["replay", str(out), "--video", str(tmp_path / "demo.mp4")]), tmp_path)
    assert video.returncode == 2 and video.stdout == "", video.stderr
    assert video.stderr.splitlines() == [
        "gym-fetch replay: error: MUJOCO_GL=osmesa needs the OSMesa library (libOSMesa.so), which is not "
        "installed: apt-get install libosmesa6, or use MUJOCO_GL=egl (libEGL, from libegl1)"]
