"""The collection window for real: a session under Xvfb draws the scene and the HUD at the control rate."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fetch.teleop.keyboard import KeyboardState, keyboard_command
from fetch.teleop.viewer import camera_yaw

SCRIPT = pathlib.Path(__file__).parent / "scripts" / "viewer_session.py"


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (apt-get install xvfb)")
def test_viewer_shows_scene_and_hud_at_the_control_rate(tmp_path: pathlib.Path) -> None:
    pygame = pytest.importorskip("pygame")
    shot = tmp_path / "shot.png"
    # As on a desktop: MuJoCo renders through the display's GL (this process chose EGL, having none).
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    run = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1024x768x24", sys.executable, str(SCRIPT),
                          str(tmp_path / "out"), str(shot)], capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["saved"] == 2
    assert report["frames"] >= 5
    assert report["achieved_hz"] > 20.0, report  # 25 Hz asked; the window must not slow control down
    image = pygame.surfarray.array3d(pygame.image.load(str(shot))).swapaxes(0, 1)  # (H, W, 3)
    h, w, _ = image.shape
    scene = image[h // 4: 3 * h // 4]
    assert scene.std() > 20, "the scene is blank"
    hud = image[: h // 8, : w // 2]
    white = (hud > 230).all(axis=2).mean()
    assert 0.005 < white < 0.5, f"no HUD text in the top-left corner ({white:.3f} white)"
    legend = image[-h // 10:]
    assert ((legend > 200).all(axis=2)).mean() > 0.005, "no controls legend at the bottom"


def test_keyboard_mapping() -> None:
    state = KeyboardState()
    c = keyboard_command({"up"}, set(), state)
    np.testing.assert_allclose(c.action, [0, 1, 0, 1])
    c = keyboard_command({"d", "r", "left shift"}, {"space"}, state, precision_scale=0.3)
    np.testing.assert_allclose(c.action, [0.3, 0, 0.3, -1], atol=1e-6)
    assert c.precision and state.gripper_closed
    c = keyboard_command({"up"}, {"c", "return"}, state, yaw=np.pi / 2)
    np.testing.assert_allclose(c.action, [-1, 0, 0, -1], atol=1e-6)  # up in a view looking along -x
    assert c.switch_camera and c.finish and not c.discard
    assert keyboard_command(set(), {"backspace"}, state).discard
    assert keyboard_command(set(), {"escape"}, state).quit


def test_camera_relative_yaw_points_stick_up_away_from_the_viewer() -> None:
    import gymnasium as gym

    from fetch.teleop.devices import rotate

    env = gym.make("PickPlace-v2").unwrapped
    for camera in ("front", "side", "behind"):
        yaw = camera_yaw(env.model, env.data, camera)  # type: ignore[attr-defined]
        up = np.array(rotate(0.0, 1.0, yaw))
        cam = env.model.camera(camera).id  # type: ignore[attr-defined]
        forward = -env.data.cam_xmat[cam].reshape(3, 3)[:, 2][:2]  # type: ignore[attr-defined]
        assert up @ forward / np.linalg.norm(forward) > 0.999, camera
