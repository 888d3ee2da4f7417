"""Mirror images of demos (`gym-fetch train --mirror`): only where the task really is symmetric."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import fetch  # noqa: F401  (registers the ids)
from fetch import observation as ob
from fetch.cli import main
from fetch.errors import FetchError
from fetch.experts import make_expert
from fetch.learn.data import load_demos, with_reflections
from fetch.tasks import mirroring_ids

MIRRORED = list(mirroring_ids())


def _reflected_quat(q: np.ndarray) -> np.ndarray:
    """The orientation a body of orientation `q` (w, x, y, z) has in the mirror y -> -y."""
    return np.array([q[0], -q[1], q[2], -q[3]])


def test_the_classic_tables_say_they_mirror_and_the_room_tasks_do_not() -> None:
    # The room tasks' furniture stands off the plane through the start; Slide's table too.
    assert MIRRORED == ["Reach-v2", "Push-v2", "PickPlace-v2"]


def test_euler_angles_of_a_reflected_orientation_flip_their_x_and_z() -> None:
    rng = np.random.default_rng(0)
    for q in rng.normal(size=(200, 4)):
        q /= np.linalg.norm(q)
        a, b, c = ob.quat2euler(q.tolist())
        assert np.allclose(ob.quat2euler(_reflected_quat(q).tolist()), [-a, b, -c], atol=1e-12)


def test_a_joint_without_its_mirror_image_in_the_part_cannot_be_reflected() -> None:
    part = ob.joints("gripper_state", ("robot0:r_gripper_finger_joint",))
    with pytest.raises(ValueError, match="mirror image is not in the part"):
        ob.mirror((part,), 0.75, {"robot0:r_gripper_finger_joint": "robot0:l_gripper_finger_joint"})


@pytest.mark.parametrize("env_id", MIRRORED)
def test_the_scene_is_symmetric_about_the_plane(env_id: str) -> None:
    env = gym.make(env_id)
    env.reset(seed=0)
    u = env.unwrapped
    m, d = u.model, u.data
    plane = float(u.reflection().observation.offset[1]) / 2
    # What stays put: geoms of bodies neither the robot's nor moving (no joint of their own, not mocap).
    scene = [(d.geom_xpos[g].copy(), m.geom_size[g].copy()) for g in range(m.ngeom)
             if not (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, m.geom_bodyid[g]) or "").startswith("robot0")
             and int(m.body_jntnum[m.geom_bodyid[g]]) == 0 and int(m.body_mocapid[m.geom_bodyid[g]]) < 0]
    assert scene, "no fixed geoms found"
    for pos, size in scene:
        image = pos * [1, -1, 1] + [0, 2 * plane, 0]
        assert any(np.allclose(image, p, atol=2e-3) and np.allclose(size, s) for p, s in scene), (pos, size)
    env.close()


@pytest.mark.parametrize("env_id", MIRRORED)
def test_the_reflected_start_observes_as_the_reflection_of_the_start(env_id: str) -> None:
    env = gym.make(env_id)
    u = env.unwrapped
    r = u.reflection()
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        _reflect_state(u)
        seen, _ = u.observe()
        # Only the object and the goal are reflected: the settled robot is itself symmetric to within
        # its fingers' rest (0.4-1.1 mm apart), residual velocities (~5e-5 per step) and 2 um at the grip.
        assert np.allclose(seen["observation"], r.observation(obs["observation"]), atol=2e-3)
        assert np.allclose(seen["observation"][:3], r.observation(obs["observation"])[:3], atol=1e-5)
        assert np.allclose(seen["desired_goal"], r.goal(obs["desired_goal"]), atol=1e-12)
        assert np.allclose(seen["achieved_goal"], r.goal(obs["achieved_goal"]), atol=1e-9)
    env.close()


@pytest.mark.parametrize("env_id", MIRRORED)
def test_reflected_actions_from_the_reflected_start_move_the_hand_along_the_reflected_path(env_id: str) -> None:
    """The expert under DART noise from 10 starts, then its actions reflected from the reflected starts.

    The hand stays within 1 mm of its reflected path at p95 (measured over 40 seeds: Reach and
    PickPlace 0.2 mm; the arm's base is 5 mm off the plane and the fingers rest up to 1.1 mm apart),
    plus twice what the same actions do when the object starts 1 mm away. That is for Push, whose
    pushed block is chaotic and pushes back on the hand: 5.2 mm reflected, 3.9 mm shifted."""
    env = gym.make(env_id)
    u = env.unwrapped
    r = u.reflection()
    expert = make_expert(env)
    rng = np.random.default_rng(1)
    reflected, shifted = [], []
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        actions, path = [], []
        for _ in range(50):
            a = np.clip(expert.act(obs) + rng.normal(0.0, 0.1, 4), -1.0, 1.0)
            actions.append(a)
            obs, *_ = env.step(a)
            path.append(obs["observation"][:3])
        env.reset(seed=seed)
        _reflect_state(u)
        for a, grip in zip(actions, path, strict=True):
            obs, *_ = env.step(a * r.action_sign)
            reflected.append(float(np.abs(r.observation(obs["observation"])[:3] - grip).max()))
        env.reset(seed=seed)
        if hasattr(u.task, "object"):
            u.data.qpos[u.task.object.qpos + 1] += 1e-3
            mujoco.mj_forward(u.model, u.data)
        for a, grip in zip(actions, path, strict=True):
            obs, *_ = env.step(a)
            shifted.append(float(np.abs(obs["observation"][:3] - grip).max()))
    assert np.median(reflected) < 2e-4, np.median(reflected)
    assert np.percentile(reflected, 95) < 1e-3 + 2 * np.percentile(shifted, 95), (
        np.percentile(reflected, 95), np.percentile(shifted, 95))
    env.close()


def _reflect_state(u: gym.Env) -> None:
    """Reflect the object (if any) and the goal of a freshly reset env in its plane."""
    r = u.reflection()
    u.data.mocap_pos[u._goal_mocap] = r.goal(u.goal)  # the goal lives in MjData (FetchEnv.goal)
    if hasattr(u.task, "object"):
        q = u.data.qpos[u.task.object.qpos:u.task.object.qpos + 7]
        q[:3] = r.goal(q[:3].copy())
        q[3:] = _reflected_quat(q[3:].copy())
    mujoco.mj_forward(u.model, u.data)


def test_a_task_that_is_not_symmetric_names_the_ones_that_are() -> None:
    env = gym.make("Slide-v2")
    with pytest.raises(FetchError, match="Slide-v2 is not symmetric.*Reach-v2, Push-v2, PickPlace-v2"):
        env.unwrapped.reflection()
    env.close()


def test_reflections_add_a_mirror_image_of_each_training_demo(tmp_path) -> None:  # noqa: ANN001
    assert main(["collect", "--env", "Push-v2", "--device", "expert", "--episodes", "4", "--render", "none",
                 "--max-steps", "20", "--out", str(tmp_path / "d")]) == 0
    demos = load_demos(tmp_path / "d")
    both = with_reflections(demos)
    assert both.valid == demos.valid and both.seeds == demos.seeds
    assert both.train[:len(demos.train)] == demos.train
    env = gym.make("Push-v2")
    r = env.unwrapped.reflection()
    size = env.observation_space["observation"].shape[0]
    for e, m in zip(demos.train, both.train[len(demos.train):], strict=True):
        assert m.name == f"{e.name} (mirrored)"
        assert np.allclose(m.obs[:, :size], r.observation(e.obs[:, :size]), atol=1e-6)
        assert np.allclose(m.obs[:, size:], r.goal(e.obs[:, size:]), atol=1e-6)
        assert np.array_equal(m.actions[:, [0, 2, 3]], e.actions[:, [0, 2, 3]])
        assert np.array_equal(m.actions[:, 1], -e.actions[:, 1])
        # The demo's own goal: y on the other side of the plane, the same distance from it.
        plane = r.goal.offset[1] / 2
        assert np.allclose(m.achieved[:, 1] - plane, plane - e.achieved[:, 1], atol=1e-6)
        # Reflecting twice gives the demo back.
        assert np.allclose(r.observation(r.observation(e.obs[:, :size])), e.obs[:, :size], atol=1e-6)
    assert not math.isclose(float(np.abs(both.train[-1].obs[:, 1] - demos.train[-1].obs[:, 1]).max()), 0.0)
    env.close()
