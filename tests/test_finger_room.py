"""`finger_room`: how wide the fingers may open around an object before one comes down on what stands beside
it, in real MuJoCo: a block set beside the bin's wall, the hand brought down on it with the fingers opened
fully (a finger lands on the rim) and as wide as `finger_room` says (it reaches the block)."""

from __future__ import annotations

import pathlib
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import fetch  # noqa: F401  (registers the envs)
from fetch.cli import main as cli_main
from fetch.dataset import open_dataset
from fetch.experts.base import Expert
from fetch.generate.attempt import Generator, Options
from fetch.generate.room import finger_room
from fetch.generate.segments import Segment
from fetch.robot import ACTION_STEP
from fetch.tasks import bin as bin_task
from fetch.tasks.subtasks import Frame, Scene

OPEN = 0.05
"""[m] a finger's full opening (the pad's X)."""


def beside_the_bin(env: Any, gap: float) -> np.ndarray:
    """Put the block on the table below the hand and the bin beside it, its wall's outer face `gap` [m] from the
    block's face along +y (the fingers' axis); the block's centre."""
    base = env.unwrapped
    env.reset(seed=0)
    grip = base.data.site_xpos[Scene(base.model).grip].copy()
    block = np.array([grip[0], grip[1] - 0.05, bin_task.REST_ON_TABLE])
    base.task.block.place(base.data, block)
    base.data.mocap_pos[base.task.bin_mocap] = (block[0], block[1] + bin_task.BLOCK + gap + bin_task.OUTER,
                                                bin_task.TABLE_TOP)
    mujoco.mj_forward(base.model, base.data)
    return block


def come_down(env: Any, block: np.ndarray, opening: float) -> tuple[float, bool, np.ndarray]:
    """Open the fingers to `opening` [m] above the block, then bring the grip down to its centre. ([m] the
    grip's height above the block's centre at the end, whether a finger touched the bin, the fingers' centres
    when they had opened)."""
    base = env.unwrapped
    scene = Scene(base.model)
    bin_body = scene.body("bin")
    fingers = [np.flatnonzero(base.model.geom_bodyid == f) for f in scene.fingers]
    obs, _ = base.observe()
    touched, opened = False, np.zeros((2, 3))
    for step in range(70):
        grip = base.data.site_xpos[scene.grip]
        target = block + [0.0, 0.0, 0.10 if step < 25 else 0.0]
        move = np.clip((target - grip) / ACTION_STEP, -1.0, 1.0)
        a3 = Expert.finger_servo(obs, base.observation_layout, opening)
        obs, *_ = env.step(np.append(move, a3).astype(np.float32))
        if step == 24:
            opened = np.array([base.data.geom_xpos[g].mean(axis=0) for g in fingers])
        d = base.data
        for c in d.contact[: d.ncon]:
            pair = {int(base.model.geom_bodyid[c.geom1]), int(base.model.geom_bodyid[c.geom2])}
            touched |= bin_body in pair and bool(pair & set(scene.fingers))
    return float(base.data.site_xpos[scene.grip][2] - block[2]), touched, opened


@pytest.mark.parametrize("gap", [0.02, 0.025, 0.03])
def test_fingers_opened_as_finger_room_says_reach_a_block_beside_the_bin_where_fully_open_ones_land_on_it(
        gap: float) -> None:
    env = gym.make("Bin-place-v2")
    base = env.unwrapped
    try:
        block = beside_the_bin(env, gap)
        scene = Scene(base.model)
        room = finger_room(base.model, base.data, scene.fingers, scene.body("block"), block, block, 0.0, OPEN)
        assert room is not None and bin_task.BLOCK < room < OPEN, room

        height, touched, _ = come_down(env, beside_the_bin(env, gap), OPEN)
        assert touched and height > 0.03, (height, touched)  # fully open: on the rim, the hand held up

        height, touched, opened = come_down(env, beside_the_bin(env, gap), room)
        assert not touched and height < 0.01, (height, touched)
        # midway: the gap between the block and the wall-side finger is the gap between it and the wall
        finger = opened[int(np.argmax(opened[:, 1]))]
        half = 0.007  # the finger's half thickness along y (the robot's model)
        inner, outer = finger[1] - half - block[1], block[1] + bin_task.BLOCK + gap - (finger[1] + half)
        assert abs((inner - bin_task.BLOCK) - outer) < 0.003, (inner - bin_task.BLOCK, outer)
    finally:
        env.close()


def test_where_the_hand_comes_down_moves_the_opening_with_it() -> None:
    """The wall-side finger stays midway in the gap wherever along the axis the hand comes down; so far
    towards the wall that the other finger would land on the block, no opening is given (None)."""
    env = gym.make("Bin-place-v2")
    base = env.unwrapped
    try:
        block = beside_the_bin(env, 0.02)
        scene = Scene(base.model)
        body = scene.body("block")
        centred = finger_room(base.model, base.data, scene.fingers, body, block, block, 0.0, OPEN)
        away = finger_room(base.model, base.data, scene.fingers, body, block, block - [0.0, 0.005, 0.0], 0.0, OPEN)
        towards = finger_room(base.model, base.data, scene.fingers, body, block, block + [0.0, 0.015, 0.0], 0.0, OPEN)
        assert centred is not None and away == pytest.approx(centred + 0.005, abs=1e-6)
        assert towards is None
    finally:
        env.close()


def test_nothing_near_leaves_the_opening_alone() -> None:
    """Only what a finger would touch counts: not the hand's own geoms, not its drawn-only mocap cross (whose
    vertical bar stands 5 cm from the block here, in the rays' way), not the table below."""
    for env_id, name in (("PickPlace-v2", "object0"), ("Bin-place-v2", "block")):
        env = gym.make(env_id)
        base = env.unwrapped
        try:
            env.reset(seed=0)
            model, data = base.model, base.data
            scene = Scene(model)
            body = scene.body(name)
            grip = data.site_xpos[scene.grip]
            centre = np.array([grip[0], grip[1] - 0.05, 0.45])
            data.qpos[model.jnt_qposadr[model.body_jntadr[body]]:][:3] = centre
            if env_id == "Bin-place-v2":  # the bin far off: 30 cm of table between the block and its wall
                data.mocap_pos[base.task.bin_mocap, 1] = centre[1] - 0.30 - bin_task.OUTER
            mujoco.mj_forward(model, data)
            assert finger_room(model, data, scene.fingers, body, centre, centre, 0.0, OPEN) is None
        finally:
            env.close()


def approach(block: np.ndarray) -> Segment:
    """A grasp segment coming straight down on `block` with the fingers fully open (a pad's X)."""
    held = block + [0.0, 0.0, 0.15]
    targets = np.array([block + [0.0, 0.0, 0.15 - 0.01 * i] for i in range(1, 16)])
    return Segment("demo_0", 0, len(targets), held, targets, np.ones(len(targets)), np.full(len(targets), OPEN),
                   Frame(block.copy(), 0.0), len(targets) - 1)


@pytest.mark.parametrize("fit", [True, False])
def test_generate_narrows_the_approach_only_beside_something(fit: bool) -> None:
    """Planned by a generator with `fit_opening`, a grasp approach carried over to a block beside the bin opens
    the fingers as `finger_room` says, and as the source did to one in the open; without, always as the source."""
    far = np.array([1.30, 0.60, bin_task.REST_ON_TABLE])
    segment = approach(far)
    generator = Generator("Bin-place-v2", {}, [[segment] * 3] * 2, Options(max_steps=50, fit_opening=fit), seed=0)
    base, scene = generator.base, generator.scene
    body = scene.body("block")
    try:
        for gap, near in ((0.02, True), (0.30, False)):
            block = beside_the_bin(generator.env, gap)
            generator._obs, _ = base.observe()
            start = block + [0.0, 0.0, 0.15]
            _, grips, openings, fitted = generator.plan(segment, Frame(block, 0.0), start, scene.loose("block"), body)
            assert openings is not None and np.all(grips == 1.0)
            room = finger_room(base.model, base.data, scene.fingers, body, block, block, 0.0, OPEN)
            assert (room is not None) == near
            assert fitted == (fit and near)
            assert generator.tight() == near
            expected = room if fit and room is not None else OPEN
            assert np.allclose(openings, expected, atol=1e-6), (gap, openings.max(), expected)
    finally:
        generator.close()


def test_a_fitted_approach_steadies_the_fingers_noise_and_an_unfitted_one_does_not() -> None:
    """`Options.steady_fit`: a step of a fitted approach perturbs a[3] by the hand's metres (noise 0.1: 0.005),
    any other step by `finger_noise` (here the default, 0.1), from the same random draws."""
    generator = Generator("Bin-place-v2", {}, [[approach(np.array([1.3, 0.6, 0.42]))] * 3],
                          Options(max_steps=50), seed=0)
    base = generator.base
    try:
        block = beside_the_bin(generator.env, 0.02)
        generator._obs, _ = base.observe()
        generator.buffer.begin(generator._obs, base.get_state())
        for steady, std in ((True, 0.1 * ACTION_STEP), (False, 0.1)):
            clean = generator._fingers(1.0, 0.03)
            draws = np.random.default_rng(7).normal(0.0, 1.0, 4)
            generator._step(block + [0.0, 0.0, 0.1], 1.0, 0.03, np.random.default_rng(7), 0, steady)
            assert np.isclose(base.last_action[3], np.clip(clean + std * draws[3], -1, 1), atol=1e-6), steady
    finally:
        generator.close()


def test_tight_starts_are_the_only_ones_attempted_when_asked() -> None:
    """`Options.starts` "tight": an attempt from a start where the block is not beside the bin is skipped (not
    made, no steps), and one from a start where it is, is made; "all" makes both."""
    segment = approach(np.array([1.3, 0.6, 0.42]))
    made: dict[str, list[bool]] = {}
    tight: list[bool] = []
    for starts in ("all", "tight"):
        generator = Generator("Bin-place-v2", {}, [[segment] * 3], Options(max_steps=8, starts=starts), seed=0)
        try:
            results = [generator.attempt(n) for n in range(40)]
            made[starts] = [r.made for r in results]
            if starts == "tight":
                for n, r in enumerate(results):
                    generator.env.reset(seed=n)
                    tight.append(generator.tight())
                    assert r.made or (r.steps == 0 and r.demo is None and not r.choices)
        finally:
            generator.close()
    assert all(made["all"]) and made["tight"] == tight and 0 < sum(tight) < len(tight), tight


def test_collect_starts_tight_attempts_from_the_tight_seeds_in_order_and_resumes_at_the_next(
        tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`collect --starts tight` (a correction round's way to where a policy is weakest): attempt k resets with the
    (k+1)-th seed from --seed on whose start a generator finds tight, a resumed session goes on with the next, the
    dataset records the choice (a session without it cannot append), and a task with no tight start is one error,
    made before its dataset folder is."""
    out = tmp_path / "tight"
    argv = ["collect", "--env", "Bin-place-v2", "--device", "expert", "--render", "none", "--keep-failures",
            "--seed", "7", "--out", str(out), "--starts", "tight", "--episodes"]
    assert cli_main([*argv, "2"]) == 0
    assert cli_main([*argv, "1"]) == 0
    generator = Generator("Bin-place-v2", {}, [[approach(np.array([1.3, 0.6, 0.42]))] * 3], Options(max_steps=8),
                          seed=0)
    try:
        expected = []
        for seed in range(7, 400):
            generator._obs, _ = generator.env.reset(seed=seed)  # as Generator.attempt sets it before its test
            if generator.tight():
                expected.append(seed)
    finally:
        generator.close()
    with open_dataset(out) as ds:
        seeds = [int(ds.attrs(n)["seed"]) for n in ds.demo_names]
        assert ds.settings["starts"] == "tight"
    assert seeds == expected[:3] and seeds[-1] - 7 > 3, (seeds, expected)  # tight ones only, in order, none again
    capsys.readouterr()
    assert cli_main(argv[:-3] + ["--episodes", "1"]) == 2  # --starts all cannot append to it
    assert "settings.starts" in capsys.readouterr().err
    assert cli_main(["collect", "--env", "PickPlace-v2", "--device", "expert", "--render", "none", "--episodes", "1",
                     "--out", str(tmp_path / "none"), "--starts", "tight"]) == 2
    said = capsys.readouterr().err.strip().splitlines()
    assert "PickPlace-v2 from seed 0 on is tight" in said[-1] and "use --starts all" in said[-1], said
    assert not any("Traceback" in line for line in said)
    assert not (tmp_path / "none").exists()  # refused before anything was made
