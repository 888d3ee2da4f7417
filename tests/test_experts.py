"""Every task's scripted expert solves it: a regression guard on a few seeds per task."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

from fetch.errors import FetchError
from fetch.experts import Expert, make_expert
from fetch.experts.base import Stage

SEEDS = range(100, 106)
_MUJOCO = tuple(int(v) for v in mujoco.__version__.split(".")[:3])
_OLD_ARM = _MUJOCO[:2] < (3, 7)
# Slide's expert (strikes, at Fetch*-v4's geometry and 50 steps, played out in its twin first) solves
# 94.5 % of the benchmark's 200 seeds on mujoco 4.0.1 (24.5 % with action noise 0.1; 93.0 % on 4.0.0).
# Its strike table is measured on 4.0.1; before 3.7 the arm moves differently (tests/test_parity_v4.py):
# there, with the table of 4.0.0, the plans alone solved 49.5 %, and played out in the twin 94.0 %.
BEFORE_MUJOCO_3_7 = pytest.mark.xfail(
    _OLD_ARM,
    reason="the strike sizes were measured on mujoco 4.0; before 3.7 the arm moves differently "
           "(tests/test_parity_v4.py) and a strike lands the puck up to 11 cm and 15 degrees elsewhere",
    strict=False)
_PUCK_EDGES_CHANGED = _MUJOCO >= (4, 0, 1)
# mujoco 4.0.1 fixed single-shot multicontact for cylinder edge collisions (its #3748, #3752): the puck is a
# cylinder, and a diagonal strike meets its edge with a fingertip's corner. The strike table and the corner's place
# (`fetch.experts.slide.CORNER`) are measured on 4.0.1; on 4.0.0 the puck goes within 2 degrees of the diagonal, on
# 4.0.1 4-6 degrees short of it (the corner slides along the rim as the hand goes on along x).


def test_make_expert_takes_an_env_or_an_id() -> None:
    assert isinstance(make_expert("Reach-v2"), Expert)
    assert isinstance(make_expert(gym.make("Drawer-open-v2")), Expert)


def test_expert_solves_the_task(env_id: str) -> None:
    env = gym.make(env_id)
    expert = make_expert(env)
    successes = 0
    for seed in SEEDS:
        obs, _ = env.reset(seed=seed)
        expert.reset()
        done = False
        while not done:
            action = expert(obs)
            assert action.shape == (4,) and action.dtype == np.float32
            assert np.all(np.abs(action) <= 1.0)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes += int(info["is_success"])
    assert successes == len(SEEDS), f"{successes}/{len(SEEDS)}"


@pytest.mark.parametrize("env_id", ["Box-close-v2", "Slide-v2"])
def test_expert_reads_only_the_observation(env_id: str) -> None:
    """An expert made from another env, which is in another state, acts the same on the same
    observations: an expert that read its env's internals (MjData) would not. (Slide's plans in a
    private copy of the task, started from the first observation.)"""
    env, other = gym.make(env_id), gym.make(env_id)
    expert, twin = make_expert(env), make_expert(other)
    other.reset(seed=99)
    for _ in range(5):
        other.step(np.float32([1.0, -1.0, 0.5, -1.0]))
    obs, _ = env.reset(seed=21 if env_id == "Slide-v2" else 3)
    for _ in range(30):
        action = expert(obs)
        np.testing.assert_array_equal(twin(obs), action)
        obs = env.step(action)[0]


def test_pick_place_expert_carries_the_block_to_a_goal_on_the_table_not_drags_it() -> None:
    """To a goal on the table the block travels lifted (2 cm and more above its rest) until it is
    above the goal, as a person carries it: a block dragged along the table slips out of the fingers
    of a policy that imitates the drag (docs/generate.md)."""
    env = gym.make("PickPlace-v2")
    expert = make_expert(env)
    carried = 0
    for seed in range(40):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        rest, goal = obs["achieved_goal"].copy(), obs["desired_goal"].copy()
        far = np.linalg.norm(goal[:2] - rest[:2])
        if goal[2] > rest[2] + 0.01 or far < 0.08:
            continue
        heights = []
        for _ in range(50):
            obs = env.step(expert(obs))[0]
            to_go = np.linalg.norm(goal[:2] - obs["achieved_goal"][:2])
            if 0.25 * far < to_go < 0.75 * far:
                heights.append(obs["achieved_goal"][2] - rest[2])
        assert heights and min(heights) > 0.02, (seed, heights)
        carried += 1
    assert carried >= 10


def test_every_registered_task_names_an_expert_that_resolves() -> None:
    from fetch._references import resolve
    from fetch.tasks import REGISTRATIONS

    for r in REGISTRATIONS:
        assert isinstance(make_expert(r.env_id), Expert), r.env_id
    for bad, problem in (("fetch.experts:nothing", "has no nothing"), ("fetch.no_such:x", "no module fetch.no_such"),
                         ("fetch.experts", "package.module:attribute")):
        with pytest.raises(FetchError, match=problem):
            resolve(bad)


def _slide_env_with_puck_gliding(velocity: tuple[float, float]) -> tuple[gym.Env, np.ndarray]:
    """Slide-v2 with the hand lifted clear and the puck at (1.0, 0.75) moving at `velocity` [m/s]."""
    env = gym.make("Slide-v2")
    env.reset(seed=0)
    base = env.unwrapped
    for _ in range(8):
        env.step(np.array([0.0, 0.0, 1.0, -1.0], dtype=np.float32))
    model = base.model
    qpos, dof = base.task.object.qpos, int(model.jnt_dofadr[model.body_jntadr[model.body("object0").id]])
    base.data.qpos[qpos:qpos + 2] = (1.0, 0.75)
    base.data.qvel[dof:dof + 6] = (*velocity, 0.0, 0.0, 0.0, 0.0)
    return env, np.array([1.0, 0.75])


@pytest.mark.parametrize("velocity", [(0.8, 0.0), (0.5, 0.5), (0.7, 0.2), (0.15, -0.6)])
def test_slide_glide_follows_the_pyramidal_friction_rule(velocity: tuple[float, float]) -> None:
    """Only the larger velocity component decelerates until both are equal, so a glide off the axes
    bends towards the diagonal; an isotropic rule (rest along the launch, v^2 / 2a away) misses
    these by 3-15 cm."""
    from fetch.experts.strikes import glide
    env, start = _slide_env_with_puck_gliding(velocity)
    puck = env.unwrapped.observation_layout["object_pos"]
    for _ in range(45):
        obs = env.step(np.array([0.0, 0.0, 0.0, -1.0], dtype=np.float32))[0]
    rest = obs["observation"][puck][:2]
    predicted = start + glide(np.asarray(velocity))
    assert np.linalg.norm(rest - predicted) < 0.015, f"rests at {rest}, predicted {predicted}"


def test_slide_launch_inverts_the_glide() -> None:
    from fetch.experts.strikes import glide, launch
    for displacement in ([0.5, 0.1], [0.3, -0.4], [0.2, 0.2], [-0.1, 0.05], [0.0, 0.3]):
        np.testing.assert_allclose(glide(launch(np.array(displacement))), displacement, atol=1e-9)


def _strikes(seeds: range) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """(line, puck before, puck at rest after, steepest tilt [deg] meanwhile) of every strike the
    expert makes on `seeds` after which the puck stops before the next one starts."""
    env = gym.make("Slide-v2")
    expert = make_expert(env)
    layout = env.unwrapped.observation_layout
    strikes = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        expert.reset()
        before, line, tilt, pushes = None, None, 0.0, 0
        for _ in range(env.spec.max_episode_steps):
            action = expert(obs)
            if expert.pushes != pushes:  # a strike starts (a previous one still gliding is dropped)
                pushes = expert.pushes
                before, line, tilt = obs["observation"][layout["object_pos"]][:2].copy(), expert.line.copy(), 0.0
            obs = env.step(action)[0]
            vec = obs["observation"]
            tilt = max(tilt, float(np.degrees(np.max(np.abs(vec[layout["object_rot"]][:2])))))
            speed = np.linalg.norm(vec[layout["object_velp"]] + vec[layout["grip_velp"]]) / 0.04
            if before is not None and expert.stage is not Stage.PUSH and speed < 0.005:
                strikes.append((line, before, vec[layout["object_pos"]][:2].copy(), tilt))
                before = None
    return strikes


@BEFORE_MUJOCO_3_7
def test_slide_strikes_send_the_puck_along_an_axis_or_a_diagonal() -> None:
    """An x strike uses one fingertip's face (the puck's centre 12 mm across, off the slot between
    the fingertips, where it wedged and tipped up to 14 degrees) and a diagonal one the corner: the
    puck goes along x, or at 45 degrees, within a few degrees (a short strike: within 8 mm of its
    line, a few mm of contact offset turning it by more degrees), and stays flat. On mujoco >= 4.0.1
    a diagonal strike goes 4-6 degrees short of 45 on these seeds (the corner placed as before 4.0.1
    sent it 15-20 degrees short)."""
    bound = 7.0 if _PUCK_EDGES_CHANGED else 4.0
    strikes = [s for s in _strikes(range(100, 112)) if s[0][0] != 0.0 and np.linalg.norm(s[2] - s[1]) > 0.05]
    assert len(strikes) >= 6
    for line, before, after, tilt in strikes:
        moved = after - before
        error = np.degrees(np.arctan2(moved[1], moved[0]) - np.arctan2(line[1], line[0]))
        across = abs(float(moved @ np.array([-line[1], line[0]]))) / float(np.linalg.norm(line))
        went = np.degrees(np.arctan2(moved[1], moved[0]))
        assert abs(error) < bound or across < 0.008, f"along {line}: went {went:.1f} deg, {across * 1000:.0f} mm off"
        assert tilt < 3.0, f"the puck tipped {tilt:.1f} degrees"


@BEFORE_MUJOCO_3_7
def test_slide_strike_sizes_land_the_puck_where_planned() -> None:
    """The strike table (action size -> distance, by the puck's x) puts the puck near the goal
    of each shot: the shots that end the episode land within 5 cm on these seeds."""
    env = gym.make("Slide-v2")
    expert = make_expert(env)
    misses = []
    for seed in (100, 102, 103, 104, 105):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        for _ in range(env.spec.max_episode_steps):
            obs, _, _, _, info = env.step(expert(obs))
        misses.append(info["distance"] if "distance" in info else np.nan)
        assert expert.pushes <= 3, f"seed {seed}: {expert.pushes} strikes"
    assert max(misses) < 0.05, f"misses {np.round(misses, 3)} m"


@BEFORE_MUJOCO_3_7
@pytest.mark.parametrize("y", [0.75, 0.5, 1.0])
def test_slide_strikes_as_hard_as_the_arm_needs_where_the_puck_is(y: float) -> None:
    """The arm is weaker to the side: a 30 cm shot along x from y = 0.5 or 1.0 m needs a harder
    strike than from in front of the shoulder (y = 0.75 m); the table knows it, and each lands."""
    from fetch.experts.strikes import strike_size

    env = gym.make("Slide-v2")
    expert = make_expert(env)
    env.reset(seed=0)
    model, data = env.unwrapped.model, env.unwrapped.data
    adr = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "object0:joint")]
    data.qpos[adr:adr + 2] = (1.2, y)
    data.mocap_pos[model.body("goal").mocapid[0], :2] = (1.5, y)
    mujoco.mj_forward(model, data)
    obs = env.step(np.zeros(4, np.float32))[0]
    expert.reset()
    sizes = []
    for _ in range(45):
        obs, _, _, _, info = env.step(expert(obs))
        if expert.stage is Stage.PUSH and expert.timer == 2:
            sizes.append(expert.size_now)
    assert len(sizes) == 1, f"{len(sizes)} strikes"
    assert info["distance"] < 0.03, f"from y = {y}: {info['distance'] * 100:.1f} cm off the goal"
    centre, here = (strike_size(0.3, np.array([1.2, y0]), np.array([1.0, 0.0])) for y0 in (0.75, y))
    if y != 0.75:
        assert here > centre + 0.03, f"size {here:.2f} from y = {y}, {centre:.2f} from the centre"


def test_slide_twin_follows_the_episode_exactly_until_it_gets_another_action() -> None:
    """The Slide expert's private copy of the task starts where the episode started, from its first
    observation, and stays bit-identical while the env gets the expert's actions; one action that
    differs puts it out of step for good."""
    env = gym.make("Slide-v2")
    expert = make_expert(env)
    twin = expert.twin  # type: ignore[attr-defined]
    obs, _ = env.reset(seed=7)
    expert.reset()
    for _ in range(20):
        obs = env.step(expert(obs))[0]
    expert(obs)
    assert twin.in_step
    np.testing.assert_array_equal(twin.obs["observation"], obs["observation"])
    obs = env.step(expert.sent + np.float32([0.01, 0.0, 0.0, 0.0]))[0]  # type: ignore[attr-defined]
    expert(obs)
    assert not twin.in_step
    obs, _ = env.reset(seed=8)
    expert.reset()
    expert(obs)
    assert twin.in_step


def test_slide_plays_its_plan_out_in_the_twin_and_strikes_first_what_lands() -> None:
    """Seed 47: the strike table's plan ends 16 cm from the goal (on mujoco 4.0.1, where the table was measured;
    on 3.3 and 4.0.0 it happens to win this seed); played out in the twin it falls short, and a first strike
    chosen there wins the episode."""
    from fetch.experts.slide import Slide
    env = gym.make("Slide-v2")

    def distance(expert: Expert) -> float:
        obs, _ = env.reset(seed=47)
        expert.reset()
        for _ in range(50):
            obs, _, _, _, info = env.step(expert(obs))
        return float(info["distance"])

    if _PUCK_EDGES_CHANGED:  # the premise holds where the table was measured
        assert distance(Slide(env.unwrapped.observation_layout)) > 0.05  # type: ignore[attr-defined]
    assert distance(make_expert(env)) < 0.05


def test_slide_hurries_a_shot_that_would_still_glide_at_the_last_step() -> None:
    """Success is judged at the last step: a shot struck to stop on the goal but still gliding by
    then is struck harder instead, so as to be just short of the goal at the last step."""
    from fetch.experts.slide import Slide
    expert = Slide(gym.make("Slide-v2").unwrapped.observation_layout)
    expert.line, expert.target = np.array([1.0, 0.0]), np.array([1.6, 0.75])
    expert.goal = expert.target.copy()
    expert.steps = 10
    assert expert.hurry(0.4) == pytest.approx(0.4)  # 40 steps left: time to stop on the goal
    expert.steps = 38
    assert expert.hurry(0.4) > 0.45  # 10 steps left: the puck has to be moving fast at the end
    expert.target = np.array([1.3, 0.75])  # not a shot at the goal: a first strike is never hurried
    assert expert.hurry(0.4) == pytest.approx(0.4)
