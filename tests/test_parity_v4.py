"""Reach/Push/PickPlace/Slide-v2 against rollouts recorded from gymnasium-robotics' Fetch*-v4.

The reference (tests/data/v4_reference.npz) was recorded on mujoco 3.11 by
`python -m benchmarks.parity_v4 --record tests/data/v4_reference.npz` (from the repository's root), run
in the virtualenv that `python -m benchmarks.parity_v4 --venv DIR` makes; this test needs neither that mujoco nor
gymnasium-robotics' env code, so it checks parity on every mujoco version the suite runs on.
"""

from __future__ import annotations

import pathlib

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import fetch  # noqa: F401 (registers the ids)

REFERENCE = pathlib.Path(__file__).parent / "data" / "v4_reference.npz"
TASKS = ("Reach", "Push", "PickPlace", "Slide")


@pytest.fixture(scope="module")
def reference() -> dict[str, np.ndarray]:
    with np.load(REFERENCE) as data:
        return {key: data[key] for key in data.files}


@pytest.mark.parametrize("task", TASKS)
def test_same_seed_same_start_and_goal(reference: dict[str, np.ndarray], task: str) -> None:
    env = gym.make(f"{task}-v2")
    for i, seed in enumerate(reference[f"{task}/reset_seeds"]):
        obs, _ = env.reset(seed=int(seed))
        np.testing.assert_allclose(obs["observation"], reference[f"{task}/reset_observation"][i], rtol=0, atol=1e-6)
        np.testing.assert_allclose(obs["desired_goal"], reference[f"{task}/reset_goal"][i], rtol=0, atol=1e-6)


_MUJOCO = tuple(int(v) for v in mujoco.__version__.split(".")[:3])
BEFORE_3_7 = pytest.mark.xfail(
    _MUJOCO[:2] < (3, 7),
    reason="before mujoco 3.7.0 (bisected: 3.6.0 drifts, 3.7.0 does not) the hand drifts ~0.3 mm a step "
           "from v4's path when the target moves (grip p50 6-7 mm, p95 13 mm over these rollouts on 3.3.0; "
           "4.0.0: 0.04 / 0.5 mm): an engine change in 3.7.0, the model being the same",
    strict=False)

ON_TABLE = 0.39
"""[m] below this the object has left the table top (fallen off or through it)."""

_PUCK_EDGES_CHANGED = pytest.mark.xfail(
    _MUJOCO >= (4, 0, 1),
    reason="mujoco 4.0.1 fixed single-shot multicontact for cylinder edge collisions (its #3748, #3752), and "
           "Slide's puck is a cylinder: where a finger meets its edge it moves otherwise than in v4 on 3.11 "
           "(object p50 0.4 um, p95 5.1 cm, max 8.1 cm over these rollouts; 4.0.0 within the bounds)",
    strict=False)


@BEFORE_3_7
@pytest.mark.parametrize("task", [pytest.param(t, marks=_PUCK_EDGES_CHANGED) if t == "Slide" else t for t in TASKS])
def test_same_actions_same_motion(reference: dict[str, np.ndarray], task: str) -> None:
    """Over the random-action rollouts, the issue's bounds: grip site <= 5 mm at p95 and <= 2 cm at
    most, object <= 1 cm at p95; both envs agree on is_success at (nearly) every step.

    On mujoco 3.11 the motion is the same to ~1e-15 m (benchmarks/parity_v4.py, live). On other
    versions MuJoCo's own changes let hard contacts end up elsewhere now and then: a gliding puck
    that sinks through the table (Fetch*-v4 does it too, in ~7 % of random rollouts) does so in
    other rollouts. Steps after the object left the table in either run are not compared, and at
    most one rollout in ten may have that. The two scripted patterns are left to the benchmark:
    on mujoco 4 the full diagonal back into the table ends up to 6 cm elsewhere.
    """
    env = gym.make(f"{task}-v2")
    layout = env.unwrapped.observation_layout
    grip_diff, object_diff, agree, fell = [], [], [], 0
    rollouts = zip(reference[f"{task}/seeds"], reference[f"{task}/actions"], reference[f"{task}/positions"],
                   reference[f"{task}/success"], reference[f"{task}/kinds"], strict=True)
    for seed, actions, positions, success, kind in rollouts:
        if kind != "random":
            continue
        obs, _ = env.reset(seed=int(seed))
        for t, action in enumerate(actions):
            obs, _, _, _, info = env.step(action)
            vector, theirs = obs["observation"], positions[t + 1]
            if "object_pos" in layout:
                ours = vector[layout["object_pos"]]
                if min(ours[2], theirs[5]) < ON_TABLE:
                    fell += ours[2] < ON_TABLE or theirs[5] < ON_TABLE
                    break
                object_diff.append(np.linalg.norm(ours - theirs[3:6]))
            grip_diff.append(np.linalg.norm(vector[layout["grip_pos"]] - theirs[:3]))
            agree.append(info["is_success"] == success[t])
    assert np.percentile(grip_diff, 95) <= 0.005 and max(grip_diff) <= 0.02, np.percentile(grip_diff, [50, 95, 100])
    if object_diff:
        assert np.percentile(object_diff, 95) <= 0.01, np.percentile(object_diff, [50, 95, 100])
    assert fell <= 1
    assert np.mean(agree) >= 0.98


def test_the_reference_is_what_it_says() -> None:
    """A guard on the guard: the recorded rollouts move (so matching them means something)."""
    with np.load(REFERENCE) as data:
        assert "mujoco 3.11" in str(data["versions"][0])
        for task in TASKS:
            positions = data[f"{task}/positions"]
            assert positions.shape[1] == 51
            assert np.ptp(positions[:, :, :3], axis=1).max() > 0.2  # [m] the hand travels
