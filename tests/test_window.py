"""The collection window as a person sees it (issue 40), checked by numbers: depth cues that leave the env
alone, the hand's height read right, and under Xvfb a real window's shadows, inset, HUD and legend at
640 x 480 and at full screen."""

from __future__ import annotations

import json
import pathlib
import shutil
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import fetch
from fetch.teleop.scenery import VIEWPOINTS, Scenery

SCRIPT = pathlib.Path(__file__).parent / "scripts" / "window_shots.py"


@pytest.mark.parametrize("env_id", fetch.ENV_IDS)
def test_the_window_dresses_its_own_copy_and_reads_the_hand_height(env_id: str) -> None:
    env = gym.make(env_id)
    base = env.unwrapped
    env.reset(seed=1)
    before = base.model_hash()
    scenery = Scenery(env)
    assert base.model_hash() == before == gym.make(env_id).unwrapped.model_hash()  # the env is untouched
    assert scenery.model.nq == base.model.nq and scenery.model.nmocap == base.model.nmocap
    assert scenery.model.light_castshadow.any() and scenery.cameras[: len(VIEWPOINTS)] == list(VIEWPOINTS)
    assert base.task.view in scenery.cameras
    # Raised to 10 cm over the table where nothing stands, the fingertips read 10 cm over it.
    grip = base.model.site("robot0:grip").id
    for _ in range(40):
        target = np.array([1.15, 0.55, 0.4 + 0.10 + scenery.fingertips])
        env.step(np.r_[np.clip((target - base.data.site_xpos[grip]) / 0.05, -1, 1), 1.0])
    scenery.sync(base.data)
    assert scenery.below is not None and scenery.height is not None
    fingertips = base.data.site_xpos[grip][2] - scenery.fingertips
    assert scenery.below[2] == pytest.approx(0.4, abs=1e-6), "the surface below is the table top"
    assert scenery.height == pytest.approx(fingertips - 0.4, abs=1e-6)
    assert scenery.height == pytest.approx(0.10, abs=0.01)


def brightness(image: np.ndarray, xy: list[int], half: int = 2) -> float:
    x, y = xy
    return float(image[y - half: y + half + 1, x - half: x + half + 1].mean())


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (apt-get install xvfb)")
@pytest.mark.parametrize("env_id", ["PickPlace-v2", "Drawer-open-v2"])
def test_a_real_window_shows_shadows_an_inset_and_everything_inside_it(env_id: str, tmp_path: pathlib.Path) -> None:
    pygame = pytest.importorskip("pygame")
    from test_viewer import desktop_env

    run = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1024x768x24", sys.executable, str(SCRIPT), env_id,
                          str(tmp_path)], capture_output=True, text=True, timeout=300, env=desktop_env())
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["camera"] == ("left" if env_id.startswith("Drawer") else "operator")
    sizes = {name: tuple(report[name]["size"]) for name in ("window", "full", "back")}
    assert sizes == {"window": (640, 480), "full": (1024, 768), "back": (640, 480)}, sizes
    for name in ("window", "full", "back"):
        shot = report[name]
        image = pygame.surfarray.array3d(pygame.image.load(str(tmp_path / f"{name}.png"))).swapaxes(0, 1)
        height, width, _ = image.shape
        assert (width, height) == tuple(shot["size"])
        # The hand's shadow: the table beside the spot below it is darker than the table in the light.
        shade = np.median([brightness(image, xy) for xy in shot["shade"]])
        lit = brightness(image, shot["lit"])
        assert lit > 180 and shade < 0.7 * lit, (name, shade, lit)
        layout = shot["layout"]
        # Everything inside the window, the HUD beside the inset (not over it), the legend below both.
        for part in ("scene", "inset", "hud", "legend"):
            left, top, w, h = layout[part]
            assert left >= 0 and top >= 0 and left + w <= width and top + h <= height, (name, part, layout)
        inset, hud, legend = layout["inset"], layout["hud"], layout["legend"]
        assert hud[0] + hud[2] <= inset[0] and inset[1] + inset[3] <= legend[1], layout
        # The legend: every control on a line that fits, and drawn (light text on its panel's every line).
        lines = shot["legend"]
        assert all(item in " ".join(lines) for item in ("Z: rewind", "F11: full screen", "ESC: quit"))
        assert legend[3] >= 22 * len(lines)
        rows = image[legend[1]:legend[1] + legend[3], : legend[2]]
        for i in range(len(lines)):
            text = rows[4 + 22 * i: 4 + 22 * (i + 1)]
            assert (text > 200).all(axis=2).mean() > 0.01, (name, i, lines[i])
        # The inset: a picture (not blank) inside a white frame.
        left, top, w, h = inset
        assert (image[top - 1, left: left + w] > 250).all(), "no frame round the inset"
        assert image[top: top + h, left: left + w].std() > 15, "the inset is blank"
