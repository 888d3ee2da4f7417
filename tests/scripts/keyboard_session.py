"""Run by tests/test_viewer.py under Xvfb: a person's keyboard session, typed by xdotool.

Usage: keyboard_session.py OUT -- starts `gym-fetch collect --device keyboard` with its window,
finds the window, and sends real X key events (XTEST, as a keyboard does): hold R (up), tap space
(close the gripper), Enter (keep the attempt: it failed, --keep-failures keeps it), hold Left,
Backspace (discard), Escape (quit). Prints the collector's exit code and output as JSON.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time


def xdotool(*args: str) -> str:
    return subprocess.run(["xdotool", *args], check=True, capture_output=True, text=True, timeout=60).stdout


def main(out: str) -> None:
    collector = subprocess.Popen([sys.executable, "-m", "fetch.cli", "collect", "--env", "Reach-v2", "--device",
                                  "keyboard", "--keep-failures", "--max-steps", "400", "--render", "human",
                                  "--out", out], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # The collector's visible window (SDL also makes hidden ones); no window manager runs, so
        # give it the focus and put the pointer over it, then let the session start.
        window = xdotool("search", "--sync", "--onlyvisible", "--pid", str(collector.pid)).split()[-1]
        xdotool("windowfocus", "--sync", window)
        xdotool("mousemove", "--window", window, "100", "100")
        time.sleep(2.0)
        for step in (("keydown", "r"), 0.6, ("keyup", "r"), ("key", "space"), 0.4, ("key", "Return"), 1.0,
                     ("keydown", "Left"), 0.4, ("keyup", "Left"), ("key", "BackSpace"), 1.0):
            if isinstance(step, float):
                time.sleep(step)
            else:
                xdotool(*step)
        for _ in range(30):  # Escape until it has quit (a loaded machine may take a moment to notice)
            xdotool("key", "Escape")
            try:
                collector.wait(timeout=1.0)
                break
            except subprocess.TimeoutExpired:
                continue
    finally:
        if collector.poll() is None:
            collector.kill()
        output, _ = collector.communicate(timeout=60)
    print(json.dumps({"code": collector.returncode, "output": output}))


if __name__ == "__main__":
    os.environ.pop("MUJOCO_GL", None)  # as on a desktop: the display's GL
    main(sys.argv[1])
