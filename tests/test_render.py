"""Rendering: headless rgb and depth from every named camera, and a real window under Xvfb."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest

CAMERAS = ("front", "side", "behind", "wrist")


def test_headless_backend_is_chosen_for_renderers_not_set_at_import() -> None:
    if os.environ.get("DISPLAY") or sys.platform != "linux":
        pytest.skip("only meaningful on a headless Linux machine")
    from fetch._gl import backend

    assert backend() in ("egl", "osmesa")


@pytest.mark.parametrize("camera", CAMERAS)
def test_rgb_from_every_camera_is_not_blank(env_id: str, camera: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array", width=96, height=80, camera_name=camera)
    env.reset(seed=0)
    image = env.render()
    env.close()
    assert image.shape == (80, 96, 3) and image.dtype == np.uint8
    # Not one flat colour: a real scene has many distinct colours and visible contrast.
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 20
    assert image.std() > 10


def test_depth_is_metric_and_varies(env_id: str) -> None:
    env = gym.make(env_id, render_mode="depth_array", width=64, height=64)
    env.reset(seed=0)
    depth = env.render()
    env.close()
    assert depth.shape == (64, 64) and np.all(np.isfinite(depth))
    # [m] the nearest surface seen from the front camera is the table's edge, about a metre away;
    # background pixels are at the far plane.
    assert 0.3 < depth.min() < 3.0
    assert np.ptp(depth[depth < 3.0]) > 0.05


def test_goal_marker_can_be_hidden() -> None:
    images = {}
    for hide in (False, True):
        env = gym.make("Reach-v2", render_mode="rgb_array", width=128, height=128, hide_goal=hide)
        env.reset(seed=0)
        images[hide] = env.render().astype(int)
        env.close()
    # The marker is a red sphere: hiding it removes strongly red pixels and changes nothing else much.
    red = lambda im: (im[..., 0] > 150) & (im[..., 1] < 80) & (im[..., 2] < 80)  # noqa: E731
    assert red(images[False]).sum() > 5
    assert red(images[True]).sum() < red(images[False]).sum()


def test_human_mode_without_display_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import fetch

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    env = gym.make("Reach-v2", render_mode="human")
    with pytest.raises(fetch.FetchError, match="needs a display"):
        env.reset(seed=0)


_WINDOW_SCRIPT = textwrap.dedent("""
    import warnings, time
    import gymnasium as gym
    import fetch
    from gymnasium.utils.env_checker import check_env
    env = gym.make("Bin-pick-v2", render_mode="human")
    env.reset(seed=0)
    start = time.perf_counter()
    for _ in range(10):
        env.step(env.action_space.sample())
    elapsed = time.perf_counter() - start
    env.close()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make("Drawer-open-v2", render_mode="rgb_array").unwrapped)
    other = [str(w.message) for w in caught if "infinity" not in str(w.message)]
    print("ELAPSED", elapsed)
    print("OTHER", other)
""")


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="xvfb-run is not installed (apt-get install xvfb)")
def test_human_window_under_xvfb_and_full_check_env() -> None:
    """A real window (MuJoCo's viewer) in a subprocess: the viewer may crash at interpreter exit."""
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    result = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x1024x24", sys.executable, "-c",
                             _WINDOW_SCRIPT], capture_output=True, text=True, timeout=300, env=env)
    lines = dict(line.split(" ", 1) for line in result.stdout.splitlines() if line.startswith(("ELAPSED", "OTHER")))
    assert "ELAPSED" in lines, result.stdout + result.stderr
    # The viewer paces to real time: 10 steps of 0.04 s take at least ~0.4 s.
    assert float(lines["ELAPSED"]) >= 0.35
    assert lines["OTHER"] == "[]"


def test_a_render_pool_removes_the_directories_that_killed_processes_left(tmp_path, monkeypatch) -> None:  # noqa: ANN001
    """A SIGKILLed process runs no cleanup and left its render pool's directory in $TMPDIR every time;
    the next pool removes those whose lock nobody holds, and leaves alone a running pool's (its lock
    held, whatever PID namespace it runs in) and everything that only bears the name: a user's folder
    named like a pool's (`fetch-render-123-my results`), garbage numbers (`fetch-render-²-x`, 20 digits
    - once a ValueError and an OverflowError for every user), a link, a file."""
    import fcntl
    import tempfile

    from fetch.dataset.render.frames import DIR_PREFIX, LOCK_NAME, RenderPool

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    stale, running = tmp_path / f"{DIR_PREFIX}abc", tmp_path / f"{DIR_PREFIX}def"
    for d in (stale, running):
        d.mkdir()
        (d / "0.npy").write_bytes(b"x")
        (d / LOCK_NAME).write_bytes(b"")
    held = os.open(running / LOCK_NAME, os.O_RDWR)
    fcntl.flock(held, fcntl.LOCK_EX)  # as another process's pool, perhaps in another PID namespace, holds it
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / LOCK_NAME).write_bytes(b"")
    (victim / "thesis.txt").write_text("mine")
    kept = {f"{DIR_PREFIX}123-my results", f"{DIR_PREFIX}\u00b2-x", f"{DIR_PREFIX}{10**19}-x", f"{DIR_PREFIX}999999-y"}
    for name in kept:
        (tmp_path / name).mkdir()
        (tmp_path / name / "notes.txt").write_text("mine")
    (tmp_path / f"{DIR_PREFIX}link").symlink_to(victim)
    (tmp_path / f"{DIR_PREFIX}file").write_text("mine")
    try:
        with RenderPool("Reach-v2", {}, 16, workers=1) as pool:
            assert pool._dir.parent == tmp_path and pool._dir.name.startswith(DIR_PREFIX)
            assert not stale.exists() and running.exists()
            assert all((tmp_path / name / "notes.txt").read_text() == "mine" for name in kept)
            assert (victim / "thesis.txt").read_text() == "mine" and (tmp_path / f"{DIR_PREFIX}file").exists()
            with RenderPool("Reach-v2", {}, 16, workers=1) as second:  # a second pool sees the first one running
                assert pool._dir.exists() and second._dir != pool._dir
        assert not pool._dir.exists() and not second._dir.exists()
    finally:
        os.close(held)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted([running.name, "victim", f"{DIR_PREFIX}link", f"{DIR_PREFIX}file", *kept])


def test_render_ahead_closed_early_leaves_cancelling_its_jobs_to_the_pool(monkeypatch) -> None:  # noqa: ANN001
    """A consumer that stops early (Ctrl-C in `render-obs`) closes render_ahead with demos still waiting.
    It cancelled their futures itself, and on CPython 3.11 a future cancelled from outside that the pool's
    thread has not yet seen when the pool breaks (its workers terminated by the close) ends that thread
    with InvalidStateError and a traceback (CI, once). The pool's shutdown cancels them instead."""
    import concurrent.futures
    import threading

    from fetch.dataset.render.render_ahead import render_ahead

    callers: list[str] = []
    cancel = concurrent.futures.Future.cancel

    def recorded(future: concurrent.futures.Future) -> bool:
        callers.append(threading.current_thread().name)
        return cancel(future)

    errors: list[BaseException | None] = []
    monkeypatch.setattr(concurrent.futures.Future, "cancel", recorded)
    monkeypatch.setattr(threading, "excepthook", lambda args: errors.append(args.exc_value))
    env = gym.make("Reach-v2")
    env.reset(seed=0)
    states = np.stack([env.unwrapped.get_state()] * 5)
    env.close()
    images = render_ahead("Reach-v2", {}, 16, 2, ((f"demo_{i}", states, i) for i in range(12)), ("front",))
    assert next(images)["front"].shape == (5, 16, 16, 3)
    images.close()
    assert threading.main_thread().name not in callers
    assert errors == []
