"""Every task's scripted expert solves it: a regression guard on a few seeds per task."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from fetch.experts import Expert, make_expert

SEEDS = range(100, 106)
SLIDE_NOT_RETUNED = pytest.mark.xfail(
    reason="Slide-v2 is back at Fetch*-v4's geometry and 50 steps; its expert, built for a robot 20 cm "
           "closer and 115 steps, now solves ~10 % and has not been redone yet (issue 15 stays open)",
    strict=False)


def test_make_expert_takes_an_env_or_an_id() -> None:
    assert isinstance(make_expert("Reach-v2"), Expert)
    assert isinstance(make_expert(gym.make("Drawer-open-v2")), Expert)


def test_expert_solves_the_task(env_id: str, request: pytest.FixtureRequest) -> None:
    if env_id == "Slide-v2":
        request.applymarker(SLIDE_NOT_RETUNED)
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


def test_expert_reads_only_the_observation() -> None:
    """The same observations give the same actions, whatever env instance produced them."""
    a, b = gym.make("Box-close-v2"), gym.make("Box-close-v2")
    ea, eb = make_expert(a), make_expert(b)
    obs_a, _ = a.reset(seed=3)
    obs_b, _ = b.reset(seed=3)
    for _ in range(30):
        act_a, act_b = ea(obs_a), eb(obs_b)
        np.testing.assert_array_equal(act_a, act_b)
        obs_a = a.step(act_a)[0]
        obs_b = b.step(act_b)[0]


def test_slide_pushes_with_one_fingertip_so_the_puck_never_wedges_between_the_fingers() -> None:
    """Pushed at the slot between the fingertips, the puck wedged in, prised them apart and
    tipped up 7-14 degrees on these seeds (mujoco 4.0); on one fingertip's face it stays flat."""
    env = gym.make("Slide-v2")
    expert = make_expert(env)
    rot = env.unwrapped.observation_layout["object_rot"]
    steepest = 0.0
    for seed in (1, 7):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        done = False
        while not done:
            obs, _, terminated, truncated, _ = env.step(expert(obs))
            done = terminated or truncated
            if expert.stage == "push" and expert.axis == 0:
                roll_pitch = obs["observation"][rot][:2]
                steepest = max(steepest, float(np.degrees(np.max(np.abs(roll_pitch)))))
    assert steepest < 3.0, f"the puck tipped {steepest:.1f} degrees during a push along x"


@SLIDE_NOT_RETUNED
def test_slide_lines_up_a_shot_past_the_hands_reach_on_the_goals_line() -> None:
    """A y push normally stops 1.5 cm short of its target; lining up a shot at a goal the hand
    cannot reach it aims at the goal's line itself. Stopping short left these pucks 11-21 mm off
    the line before the shot (mean 16 mm, mujoco 4.0), and the shot's drift took some out of the goal."""
    env = gym.make("Slide-v2")
    expert = make_expert(env)
    puck = env.unwrapped.observation_layout["object_pos"]
    misses = []
    for seed in (0, 6, 7, 10, 13, 18):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        goal_y = float(obs["desired_goal"][1])
        assert obs["desired_goal"][0] > expert.stretch, f"seed {seed}: goal within the hand's reach"
        for _ in range(env.spec.max_episode_steps):
            if expert.stage == "push" and expert.axis == 0:
                break
            obs = env.step(expert(obs))[0]
        assert expert.stage == "push" and expert.axis == 0, f"seed {seed}: no push along x in time"
        assert expert.y_pushes == 1, f"seed {seed}: {expert.y_pushes} pushes along y before the shot"
        misses.append(abs(float(obs["observation"][puck][1]) - goal_y))
    assert np.mean(misses) < 0.008, f"off the goal's line by {np.round(misses, 4)} m"
