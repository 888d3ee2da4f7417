"""`collect_fetch_demo.py` accepts every flag of the seed's script, with the seed's meaning."""

from __future__ import annotations

import json
import pathlib
import subprocess
import sys

from fetch.dataset import open_dataset

ROOT = pathlib.Path(__file__).parents[1]


def test_every_seed_flag_is_accepted(tmp_path: pathlib.Path) -> None:
    events = tmp_path / "events.json"
    # the seed's scripted format: actions, a reset (discard), then quit when the list runs out
    events.write_text(json.dumps([{"action": [0, 0, 0, 0]}] * 3 + [{"action": [0, 0, 0, 0], "reset": True}]
                                 + [{"action": [0, 0, -0.2, 1], "reset": False, "quit": False}] * 12))
    out = tmp_path / "demos"
    args = ["--env", "Reach-v2", "--out", str(out), "--episodes", "0", "--max-steps", "12", "--seed", "5",
            "--control-hz", "0", "--success-hold-steps", "1", "--stop-on-success", "--ignore-env-done",
            "--respect-env-done", "--render", "none", "--device", "scripted", "--verbose", "--deadzone", "0.2",
            "--pos-scale", "0.5", "--invert-y", "--no-invert-y", "--gripper-open", "1", "--gripper-close", "-1",
            "--axis-lx", "0", "--axis-ly", "1", "--axis-lt", "2", "--axis-rt", "5", "--button-x", "2",
            "--button-y", "3", "--button-start", "7", "--scripted-json", str(events), "--keep-failures"]
    run = subprocess.run([sys.executable, str(ROOT / "collect_fetch_demo.py"), *args], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "attempt 0 (seed 5): 3 steps, ended by discard, not saved" in run.stdout
    with open_dataset(out) as ds:
        assert ds.demo_names == ["demo_0"]
        g = ds.demo("demo_0")
        assert int(g.attrs["seed"]) == 6 and 1 <= int(g.attrs["num_samples"]) <= 12
        assert ds.settings["max_steps"] == 12 and ds.settings["success_hold_steps"] == 1


def test_xbox_is_the_gamepad_and_help_lists_the_seed_flags() -> None:
    run = subprocess.run([sys.executable, str(ROOT / "collect_fetch_demo.py"), "--help"], capture_output=True,
                         text=True, timeout=60)
    assert run.returncode == 0
    for flag in ("--env", "--out", "--episodes", "--max-steps", "--seed", "--control-hz", "--success-hold-steps",
                 "--stop-on-success", "--ignore-env-done", "--respect-env-done", "--render", "--device",
                 "--verbose", "--deadzone", "--pos-scale", "--invert-y", "--no-invert-y", "--gripper-open",
                 "--gripper-close", "--axis-lx", "--axis-ly", "--axis-lt", "--axis-rt", "--button-x", "--button-y",
                 "--button-start", "--scripted-json"):
        assert flag in run.stdout, flag
    assert "xbox" in run.stdout
