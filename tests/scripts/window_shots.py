"""Run by tests/test_window.py under Xvfb: the collection window as a person sees it, measured.

Usage: window_shots.py ENV_ID DIR -- opens the viewer on ENV_ID with the keyboard's legend, drives the
hand 8 cm over the table beside the object, and saves screenshots (DIR/window.png at 640 x 480,
DIR/full.png after F11, DIR/back.png after F11 again) and, as JSON on the last line of stdout, what a
test checks them with: each shot's size, layout and legend lines, and the pixels where the point below
the hand, three points of table 2.5 cm from it towards the camera (in the hand's shadow), and a lit
patch of table away from the hand fall in the main view.
"""

from __future__ import annotations

import json
import pathlib
import sys
import time

import gymnasium as gym
import numpy as np

import fetch  # noqa: F401 (registers the envs)
from fetch.teleop.keyboard import KIND as KEYBOARD
from fetch.teleop.session import HudState
from fetch.teleop.viewer import Viewer


def pixel(viewer: Viewer, point: np.ndarray) -> list[int]:
    """Where a world point falls in the main view's image [px, (column, row) from the top left]."""
    m, d = viewer.scenery.model, viewer.scenery.data
    cam = m.camera(viewer.camera).id
    rel = d.cam_xmat[cam].reshape(3, 3).T @ (point - d.cam_xpos[cam])  # camera frame: looks along -z
    width, height = viewer.size
    f = 0.5 * height / np.tan(np.radians(m.cam_fovy[cam]) / 2)
    return [int(round(width / 2 + f * rel[0] / -rel[2])), int(round(height / 2 - f * rel[1] / -rel[2]))]


def frames(viewer: Viewer, hud: HudState, n: int) -> None:
    shown = viewer.frames + n
    deadline = time.monotonic() + 60
    while viewer.frames < shown and time.monotonic() < deadline:
        viewer.show(hud)
        time.sleep(0.04)


def main() -> None:
    env_id, out = sys.argv[1], pathlib.Path(sys.argv[2])
    env = gym.make(env_id)
    env.reset(seed=3)
    base = env.unwrapped
    # The hand 8 cm over the table beside the object, towards the viewer, not over anything else.
    viewer = Viewer(env, KEYBOARD.legend, frame_budget=None)  # everything drawn, however slow the frames
    for _ in range(60):
        grip = base.data.site_xpos[base.model.site("robot0:grip").id]
        target = np.array([1.25, 0.95, 0.4 + 0.08 + viewer.scenery.fingertips])
        env.step(np.r_[np.clip((target - grip) / 0.05, -1, 1), 1.0])
    hud = HudState(env_id=env_id, attempt=0, saved=0, target=10, step=0, max_steps=500, success=False, held=0,
                   hold_needed=10, gripper_closed=False, waiting=True)
    report: dict[str, object] = {"camera": viewer.camera, "cameras": viewer.cameras}
    for name, action in (("window", None), ("full", viewer.toggle_fullscreen), ("back", viewer.toggle_fullscreen)):
        if action is not None:
            action()
        frames(viewer, hud, 8)
        viewer.screenshot(str(out / f"{name}.png"))
        below = viewer.scenery.below
        assert below is not None
        camera = viewer.scenery.data.cam_xpos[viewer.scenery.model.camera(viewer.camera).id]
        towards = (camera - below) * [1, 1, 0]
        towards *= 0.025 / np.linalg.norm(towards)
        side = np.array([-towards[1], towards[0], 0.0])
        report[name] = {"size": viewer.size, "layout": viewer.layout, "fullscreen": viewer.fullscreen,
                        "below": pixel(viewer, below),
                        "shade": [pixel(viewer, below + d) for d in (towards, towards + side, towards - side)],
                        "lit": pixel(viewer, np.array([1.45, 0.95, 0.4])),
                        "legend": viewer.wrap(KEYBOARD.legend, viewer.size[0] - 16),
                        "height": viewer.scenery.height}
    viewer.close()
    print(json.dumps(report))


if __name__ == "__main__":
    main()
