"""The package as installed: `fetch:` ids without importing it, assets from gymnasium-robotics."""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import fetch
from fetch.scene import SCENE_XML, robot_asset_dir


def _run(code: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)


def test_fetch_prefix_makes_envs_without_importing_fetch_first() -> None:
    code = ("import gymnasium as gym, sys\n"
            "assert 'fetch' not in sys.modules\n"
            "for i in ['Bin-pick-v2', 'Drawer-close-v2', 'Slide-v2']:\n"
            "    env = gym.make('fetch:' + i); obs, _ = env.reset(seed=0); env.step(env.action_space.sample())\n"
            "print('ok')")
    result = _run(code)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok"


def test_import_does_not_import_gymnasium_robotics_or_pygame() -> None:
    """Only the asset files of gymnasium-robotics are used; nothing heavy at import."""
    result = _run("import sys, fetch, gymnasium as gym\n"
                  "gym.make('PickPlace-v2').reset(seed=0)\n"
                  "print(sorted(m for m in ('gymnasium_robotics', 'pygame', 'mujoco_py') if m in sys.modules))")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_robot_model_comes_from_gymnasium_robotics() -> None:
    root = robot_asset_dir()
    assert (root / "fetch" / "robot.xml").is_file()
    assert "gymnasium_robotics" in root.parts
    ours = pathlib.Path(fetch.__file__).parent
    assert SCENE_XML.is_file() and SCENE_XML.parent.parent == ours
    assert not list(ours.rglob("*.stl")), "the robot's meshes must not be copied into the package"


def test_import_leaves_the_environment_alone_and_rendering_still_works_headless() -> None:
    """`import fetch` sets no variable (it used to set MUJOCO_GL); the first renderer picks EGL or
    OSMesa on a headless machine all the same."""
    if sys.platform != "linux":
        return
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY", "WAYLAND_DISPLAY",
                                                              "PYOPENGL_PLATFORM")}
    code = ("import os; before = dict(os.environ); import fetch, gymnasium as gym; "
            "print(dict(os.environ) == before); e = gym.make('Reach-v2', render_mode='rgb_array', width=32, "
            "height=32); e.reset(seed=0); print(e.render().std() > 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert result.stdout.split() == ["True", "True"], result.stderr
