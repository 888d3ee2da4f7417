"""The collection window as a person sees it (issue 40), checked by numbers: depth cues that leave the env
alone, the hand's height read right, and under Xvfb a real window's shadows, inset, HUD and legend at
640 x 480 and at full screen."""

from __future__ import annotations

import json
import pathlib
import shutil
import statistics
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


def window_budget(budget: float, frames: int, tmp_path: pathlib.Path) -> tuple[dict, np.ndarray]:
    """The report of tests/scripts/window_budget.py run under Xvfb, and its last screenshot (H, W, 3)."""
    pygame = pytest.importorskip("pygame")
    from test_viewer import desktop_env

    run = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1024x768x24", sys.executable,
                          str(SCRIPT.with_name("window_budget.py")), str(budget), str(frames), str(tmp_path)],
                         capture_output=True, text=True, timeout=300, env=desktop_env())
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert len(report["shown"]) == frames, "the window did not show enough frames"
    return report, pygame.surfarray.array3d(pygame.image.load(str(tmp_path / "last.png"))).swapaxes(0, 1)


def amber_in_hud(image: np.ndarray, hud: list[int]) -> float:
    """The share of the HUD panel's pixels in its amber text: the panel darkens the scene below it."""
    left, top, w, h = hud
    panel = image[top: top + h, left: left + w].astype(int)
    return float(((panel[..., 0] > 200) & (panel[..., 1] > 160) & (panel[..., 1] < 240) & (panel[..., 2] < 140)).mean())


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (apt-get install xvfb)")
def test_a_window_over_its_frame_budget_drops_shadows_then_the_inset_by_measured_frame_times(
        tmp_path: pathlib.Path) -> None:
    from fetch.teleop.viewer import JUDGED

    report, image = window_budget(1e-6, 3 * JUDGED, tmp_path)  # every frame takes longer than a microsecond
    shown = report["shown"]
    # The first JUDGED frames, drawn in full, decide: shadows go, by their median render time.
    assert all(f["shadows"] and f["inset"] and not f["economy"] for f in shown[: JUDGED - 1])
    first = f"shadows off: frame {1e3 * statistics.median(f['seconds'] for f in shown[:JUDGED]):.0f} ms"
    assert (shown[JUDGED - 1]["shadows"], shown[JUDGED - 1]["inset"]) == (False, True)
    assert shown[JUDGED - 1]["economy"] == first
    # Then the inset, judged on frames posted after shadows went only (those in flight then do not count).
    since = [f for f in shown[JUDGED:] if f["tick"] > shown[JUDGED - 1]["ticks"]]
    median = statistics.median(f["seconds"] for f in since[:JUDGED])
    assert since[JUDGED - 1]["economy"] == f"{first}, inset off: frame {1e3 * median:.0f} ms"
    assert since[JUDGED - 2]["inset"] and not since[JUDGED - 1]["inset"]
    assert not shown[-1]["shadows"] and not shown[-1]["inset"]
    # The picture: no inset, and the HUD's amber line says what went.
    assert "inset" not in report["layout"] and image[: image.shape[0] // 4].std() > 20
    assert amber_in_hud(image, report["layout"]["hud"]) > 0.002


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (apt-get install xvfb)")
def test_a_window_within_its_frame_budget_draws_everything(tmp_path: pathlib.Path) -> None:
    from fetch.teleop.viewer import JUDGED

    report, image = window_budget(60.0, 3 * JUDGED, tmp_path)  # no frame takes a minute
    assert all(f["shadows"] and f["inset"] and not f["economy"] for f in report["shown"])
    assert "inset" in report["layout"] and amber_in_hud(image, report["layout"]["hud"]) == 0.0
