"""Demos the way people make them: the stand-in operators' habits reach the data through the real pad
path, and generation, training and the flags handle them without being told the style."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.dataset.habits import demo_flags, first_success, observation_changes, runs, still_steps
from fetch.generate.segments import tidy_steps
from fetch.generate.sources import load_sources
from fetch.tasks.subtasks import Frame
from fetch.testing import operators


def test_still_steps_are_the_ones_that_change_nothing() -> None:
    actions = np.zeros((6, 4))
    actions[:, 3] = 1.0
    actions[1, 0] = 0.5          # asks the hand to move
    actions[3, 3] = -1.0         # X: the fingers close
    changes = np.array([0.0, 0.02, 0.0, 0.0005, 0.004, 0.0])  # step 4: the fingers still closing
    assert still_steps(actions, changes).tolist() == [False, False, True, False, False, True]


def test_flags_say_what_hurts_and_where() -> None:
    steps = 60
    obs = np.cumsum(np.full((steps, 3), 0.01), axis=0)
    obs[20:35] = obs[19]  # steps 19-33 change nothing
    next_obs = np.r_[obs[1:], obs[-1:] + 0.01]
    actions = np.zeros((steps, 4))
    actions[:, :3] = 0.3
    actions[19:35, :3] = 0.0
    actions[:, 3] = 1.0
    actions[10:14, 3] = -1.0  # closed on nothing, opened again after 4 steps
    actions[40:, 3] = -1.0
    success = np.zeros(steps)
    success[50:55] = 1
    arrays = {"actions": actions, "obs/observation": obs, "next_obs/observation": next_obs, "is_success": success}
    flags = {f.kind: f for f in demo_flags(arrays, median_length=20)}
    assert set(flags) == {"idle", "chatter", "regrasp", "long", "lost"}
    assert flags["idle"].where == ((19, 34),) and flags["idle"].count == 15
    assert flags["regrasp"].count == 2 and flags["lost"].where == ((55, 60),)
    assert flags["chatter"].where == ((10, 15),)
    assert first_success(success) == 51 and runs(success > 0) == [(50, 55)]
    plain = {"actions": actions[:5], "obs/observation": obs[:5], "next_obs/observation": next_obs[:5],
             "is_success": np.ones(5)}
    assert demo_flags(plain, median_length=5) == []


def test_a_tidied_segment_leaves_out_rests_and_a_missed_grasp_and_keeps_the_grasp() -> None:
    """A grasp segment: slow approach at a quarter of full speed, a missed close 3 cm up, reopening,
    then the grasp and 15 steps resting on it. Tidied: no rest, no miss, the approach merged to the
    expert's pace, every step where the fingers act kept."""
    block = np.array([1.3, 0.75, 0.42])
    approach = [block + [0.0, 0.0, 0.30 - 0.0125 * i] for i in range(22)]  # down at 1.25 cm a step to +3.5 cm
    miss = [block + [0, 0, 0.03]] * 8
    regrasp = [block + [0, 0, 0.03 - 0.01 * i] for i in range(4)]
    rest = [block] * 15
    targets = np.array(approach + miss + regrasp + [block] * 4 + rest)
    n = len(targets)
    grips = np.ones(n)
    grips[22:26] = -1.0  # the miss: closed 4 steps (fingers moving), then open again
    grips[34:] = -1.0    # the grasp, then the rest
    openings = np.full(n, 0.05)
    openings[22:30] = np.linspace(0.05, 0.0, 8)
    openings[30:34] = 0.05
    openings[34:38] = np.linspace(0.04, 0.025, 4)
    openings[38:] = 0.025
    still = np.zeros(n, bool)
    still[38:] = True
    held = np.r_[targets[:1] + [0, 0, 0.0125], targets[:-1]]
    first, keep = tidy_steps(targets, grips, openings, still, Frame(block, 0.0), held)
    kept = set(keep.tolist())
    assert first == 0 and not kept & set(range(22, 30)), "the approach, then on where the fingers are open again"
    assert keep[-1] == 37 and not set(range(38, n)) & kept, "no resting step"
    assert set(range(34, 38)) <= kept, "every step of the real grasp"
    untidied_to_grasp = 34
    assert len(keep) < untidied_to_grasp / 2


@pytest.mark.parametrize("style", sorted(operators.STYLES))
def test_every_style_drives_the_real_pad_path_and_generation_takes_its_demos(pad, style: str,  # noqa: ANN001
                                                                             tmp_path: pathlib.Path) -> None:
    """Three PickPlace demos by each stand-in through the virtual pad; `generate` keeps at least half
    its attempts from them (no style switch: the same command for every style)."""
    human = operators.record(pad, "PickPlace-v2", style, tmp_path / "human", 3, seed=7)
    out = tmp_path / "generated"
    assert main(["generate", "--source", str(human), "--out", str(out), "--demos", "10", "--workers", "1",
                 "--max-attempts", "20"]) == 0
    with open_dataset(out) as ds:
        assert len(ds.demo_names) == 10 and max(int(ds.attrs(n)["attempt"]) for n in ds.demo_names) < 20


def test_a_rest_after_the_grasp_is_neither_generated_nor_learnt(pad, tmp_path: pathlib.Path) -> None:  # noqa: ANN001
    """The stall a person's habit caused (a policy that learnt to rest holding the block: 6 % on
    PickPlace): demos that rest 12-17 steps after the grasp. Neither the generated demos nor what
    training reads from the person's own demos hold such a rest."""
    from fetch.dataset.habits import layout_of, pose_columns
    from fetch.learn.data import learnt_steps

    layout = layout_of("PickPlace-v2")
    human = operators.record(pad, "PickPlace-v2", "rests", tmp_path / "human", 4, seed=3)
    with open_dataset(human) as ds:
        for name in ds.demo_names:
            arrays = ds.arrays(name)
            columns = pose_columns(layout, arrays["obs/observation"].shape[1])
            changes = observation_changes(arrays["obs/observation"], arrays["next_obs/observation"], columns)
            still = still_steps(arrays["actions"], changes)[:first_success(arrays["is_success"])]
            rests = [b - a for a, b in runs(still)]
            assert max(rests) >= 7, "the stand-in rests (12-17 ticks hands off, the fingers closing in the first)"
            keep = learnt_steps(arrays, layout)
            assert len(keep) - keep.sum() >= max(rests), "training leaves the rest out"
    for demo in load_sources(human).segments:  # what generation replays: no rest in any segment
        for segment in demo:
            assert segment.openings is not None
            standing = (np.linalg.norm(np.diff(segment.targets, axis=0), axis=1) < 1e-3) \
                & (np.abs(np.diff(segment.openings)) < 1e-3)
            assert max((b - a for a, b in runs(standing)), default=0) < 3, (segment.demo, segment.start)
    out = tmp_path / "generated"
    assert main(["generate", "--source", str(human), "--out", str(out), "--demos", "6", "--workers", "1"]) == 0
    with open_dataset(out) as ds:
        for name in ds.demo_names:
            done = first_success(ds.arrays(name)["is_success"])
            assert done is not None and done <= 50, name


def test_info_flags_what_a_persons_demos_hold(pad, tmp_path: pathlib.Path, capsys) -> None:  # noqa: ANN001
    human = operators.record(pad, "PickPlace-v2", "pauses", tmp_path / "human", 3, seed=1)
    assert main(["info", str(human)]) == 0
    out = capsys.readouterr().out
    assert "of 3 demos flagged" in out and "idle:" in out
    assert ": idle " in out and out.strip().endswith("valid")


def test_view_shows_the_flags_on_the_row_and_the_plot_in_chromium(pad, tmp_path: pathlib.Path) -> None:  # noqa: ANN001
    pytest.importorskip("av")
    import cdp

    human = operators.record(pad, "PickPlace-v2", "pauses", tmp_path / "human", 2, seed=1)
    page = tmp_path / "page"
    assert main(["view", str(human), "--out", str(page), "--size", "32"]) == 0
    with cdp.open_page(page / "index.html", tmp_path) as browser:
        assert browser.wait_for("window.FetchView && FetchView.state.plotted") == "demo_0"
        cells = browser.evaluate("[...document.querySelectorAll('td.flags')].map(td => [td.textContent, td.title])")
        assert len(cells) == 2 and any("idle" in kinds and "idle" in title for kinds, title in cells)
        assert browser.evaluate("document.querySelectorAll('#detail-flags li').length") >= 1
        assert browser.evaluate("document.querySelectorAll('#plots svg rect.flagged').length") >= 1
        assert browser.errors() == [] and browser.evaluate("FetchView.state.errors") == []


def test_a_grasp_redone_after_the_segment_began_holding_is_left_out() -> None:
    """A lift that begins holding (the grasp segment ended closed), lets go and grasps again: its
    replay starts at the final grasp, so a generated demo holding the object does not let go."""
    block = np.array([1.3, 0.75, 0.42])
    targets = np.array([block + [0.0, 0.0, 0.01 * i] for i in range(12)])
    grips = np.r_[np.ones(3), -np.ones(9)]
    held = np.r_[targets[:1], targets[:-1]]
    first, keep = tidy_steps(targets, grips, None, None, Frame(block, 0.0), held, holding=True)
    assert first == 3 and keep[0] >= 3, "from the final grasp: nothing held was let go"
    first, _ = tidy_steps(targets, grips, None, None, Frame(block, 0.0), held, holding=False)
    assert first == 0, "a first grasp keeps its approach"


def test_a_grasp_made_again_ends_the_grasp_subtask_where_the_last_one_did(pad, tmp_path: pathlib.Path) -> None:  # noqa: ANN001
    """Bin-pick by the `regrasp` stand-in: its first closing, 3 cm up, touches the block's top (the
    grasp signal fires), then it lets go and grasps again. The grasp segment ends at the last grasp,
    so the lift that follows begins holding, and what generation replays closes the fingers once."""
    human = operators.record(pad, "Bin-pick-v2", "regrasp", tmp_path / "human", 3, seed=0)
    with open_dataset(human) as ds:
        closings = {n: np.flatnonzero(np.diff((ds.arrays(n)["actions"][:, 3] <= -0.5).astype(int)) > 0) + 1
                    for n in ds.demo_names}
    redone = 0
    for grasp, lift, _ in load_sources(human).segments:
        assert lift.grips[0] <= -0.5, (grasp.demo, lift.start)
        closed = grasp.grips <= -0.5
        assert closed[-1] and not np.any(np.diff(closed.astype(int)) < 0), (grasp.demo, grasp.grips)
        # it ends after the demo's last closing (the grasp that held), not after the first one, 3 cm up
        assert grasp.end > closings[grasp.demo][-1], (grasp.demo, grasp.end, closings[grasp.demo])
        redone += len(closings[grasp.demo]) >= 2
    assert redone >= 1, "no demo grasped twice: the test shows nothing"
