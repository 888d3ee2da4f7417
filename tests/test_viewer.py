"""The collection window for real: a session under Xvfb draws the scene and the HUD at the control rate."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from fetch.errors import FetchError
from fetch.teleop.devices import HandControls
from fetch.teleop.keyboard import KIND as KEYBOARD
from fetch.teleop.keyboard import keyboard_command
from fetch.teleop.session import HudState
from fetch.teleop.viewer import Viewer, camera_yaw

SCRIPT = pathlib.Path(__file__).parent / "scripts" / "viewer_session.py"


def desktop_env() -> dict[str, str]:
    """This environment as a desktop session has it: MuJoCo renders through the display's GL (this
    process chose EGL, having no display) and SDL opens real X windows (not a test's dummy driver)."""
    return {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "SDL_VIDEODRIVER")}


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (apt-get install xvfb)")
def test_viewer_shows_scene_and_hud_at_the_control_rate(tmp_path: pathlib.Path) -> None:
    pygame = pytest.importorskip("pygame")
    shot = tmp_path / "shot.png"
    run = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1024x768x24", sys.executable, str(SCRIPT),
                          str(tmp_path / "out"), str(shot)], capture_output=True, text=True, timeout=300,
                         env=desktop_env())
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["saved"] == 2 and report["driver"] == "x11", report  # a real X window
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


@pytest.mark.skipif(shutil.which("xvfb-run") is None or shutil.which("xdotool") is None,
                    reason="needs xvfb-run and xdotool (apt-get install xvfb xdotool)")
def test_keyboard_drives_the_collector_through_real_key_events(tmp_path: pathlib.Path) -> None:
    from fetch.dataset import open_dataset, validate

    out = tmp_path / "out"
    run = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1024x768x24", sys.executable,
                          str(SCRIPT.with_name("keyboard_session.py")), str(out)],
                         capture_output=True, text=True, timeout=300, env=desktop_env())
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["code"] == 0, report["output"]
    assert "ended by discard, not saved" in report["output"] and "ended by quit" in report["output"]
    with open_dataset(out) as ds:
        assert validate(ds) == [] and ds.demo_names == ["demo_0"] and ds.masks()["failed"] == ["demo_0"]
        assert ds.attrs("demo_0")["device"] == "keyboard" and ds.data_attrs["attempts"] == 3
        actions = ds.demo("demo_0")["actions"][()]
    up = np.flatnonzero((actions[:, 2] == 1.0) & (actions[:, 3] == 1.0))  # R held, gripper open
    closed = np.flatnonzero(actions[:, 3] == -1.0)  # after space
    assert len(up) >= 5 and len(closed) >= 3 and up.max() < closed.min(), actions
    assert not actions[:, :2].any()  # Left was held in the discarded attempt only


def test_keyboard_mapping() -> None:
    state = HandControls()
    c = keyboard_command({"up"}, set(), state)
    np.testing.assert_allclose(c.action, [0, 1, 0, 1])
    c = keyboard_command({"d", "r", "left shift"}, {"space"}, state)
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


HUD = HudState(env_id="PickPlace-v2", attempt=0, saved=0, target=1, step=0, max_steps=50, success=False, held=0,
               hold_needed=10, gripper_closed=False)


@pytest.fixture
def make_viewer(monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[[], Viewer]]:
    """Viewers on SDL's dummy video driver (no window) with this process's offscreen GL; closed after."""
    pygame = pytest.importorskip("pygame")
    import gymnasium as gym

    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    made: list[Viewer] = []

    def make() -> Viewer:
        env = gym.make("PickPlace-v2")
        env.reset(seed=0)
        made.append(Viewer(env, KEYBOARD.legend))
        return made[-1]

    yield make
    for viewer in made:
        viewer.close()
    pygame.quit()


def show_until(viewer: Viewer, done: Callable[[], bool], timeout: float = 30.0) -> list[float]:
    """Call `show` once per 10 ms until `done()`; the time each call took [s]."""
    costs = []
    end = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < end, "timed out"
        start = time.perf_counter()
        viewer.show(HUD)
        costs.append(time.perf_counter() - start)
        time.sleep(0.01)
    return costs


def test_show_never_waits_for_a_frame_and_close_stops_the_render_thread(
        make_viewer: Callable[[], Viewer], monkeypatch: pytest.MonkeyPatch) -> None:
    import mujoco

    render = mujoco.mjr_render

    def slow_render(*args: object) -> None:  # a frame far slower than a control period
        time.sleep(0.5)
        render(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(mujoco, "mjr_render", slow_render)
    viewer = make_viewer()
    costs = show_until(viewer, lambda: viewer.frames >= 2)
    assert max(costs) < 0.25, f"show() waited for a frame: {max(costs):.3f} s"
    assert len(costs) > 20  # ticks went on while each frame took 0.5 s
    assert viewer.fps > 0
    picture = viewer.pygame.surfarray.array3d(viewer.window)
    assert picture[:, 100:380].std() > 20, "the scene is blank"
    viewer.close()
    assert not viewer._frames.running
    assert viewer._frames.error is None


def test_a_render_thread_failure_is_raised_by_show(make_viewer: Callable[[], Viewer],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    import mujoco

    viewer = make_viewer()
    show_until(viewer, lambda: viewer.frames >= 1)

    def broken(*args: object) -> None:
        raise RuntimeError("the GL driver fell over")

    monkeypatch.setattr(mujoco, "mjr_render", broken)
    with pytest.raises(FetchError, match="render thread failed: RuntimeError: the GL driver fell over"):
        show_until(viewer, lambda: False)
    assert not viewer._frames.running  # the thread ended, having freed its GL context


def test_no_opengl_is_a_fetch_error(make_viewer: Callable[[], Viewer], monkeypatch: pytest.MonkeyPatch) -> None:
    import fetch.teleop.frames

    def no_gl(*args: object) -> None:
        raise RuntimeError("no GL here")

    monkeypatch.setattr(fetch.teleop.frames, "context_class", lambda: no_gl)
    with pytest.raises(FetchError, match="viewer cannot render with MUJOCO_GL=.*no GL here"):
        make_viewer()
