"""Run by tests/test_window.py under Xvfb: the window choosing what to draw from its measured frame times.

Usage: window_budget.py BUDGET FRAMES DIR -- opens the viewer on PickPlace-v2 with `frame_budget=BUDGET` [s],
shows FRAMES frames (a tick every 10 ms), saves DIR/last.png, and prints as JSON on the last line of stdout
each shown frame's tick, render time [s], the ticks so far, and what the window drew and said after it, and
the last layout.
"""

from __future__ import annotations

import json
import pathlib
import sys
import time

import gymnasium as gym

import fetch  # noqa: F401 (registers the envs)
from fetch.teleop.keyboard import KIND as KEYBOARD
from fetch.teleop.session import HudState
from fetch.teleop.viewer import Viewer


def main() -> None:
    budget, frames, out = float(sys.argv[1]), int(sys.argv[2]), pathlib.Path(sys.argv[3])
    env = gym.make("PickPlace-v2")
    env.reset(seed=0)
    viewer = Viewer(env, KEYBOARD.legend, frame_budget=budget)
    hud = HudState(env_id="PickPlace-v2", attempt=0, saved=0, target=1, step=0, max_steps=500, success=False,
                   held=0, hold_needed=10, gripper_closed=False)
    shown = []
    deadline = time.monotonic() + 120
    while viewer.frames < frames and time.monotonic() < deadline:
        before = viewer.frames
        viewer.show(hud)
        if viewer.frames > before:
            shown.append({"tick": viewer.shown_frame.tag, "seconds": viewer.shown_frame.seconds, "ticks": viewer.ticks,
                          "shadows": viewer.shadows, "inset": viewer.inset_on, "economy": viewer.economy})
        time.sleep(0.01)
    viewer.screenshot(str(out / "last.png"))
    report = {"shown": shown, "layout": viewer.layout, "size": viewer.size}
    viewer.close()
    print(json.dumps(report))


if __name__ == "__main__":
    main()
