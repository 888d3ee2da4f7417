"""Reach/Push/PickPlace/Slide-v2 against gymnasium-robotics' Fetch*-v4, live, side by side.

Needs a virtualenv with mujoco 3.11 (the newest the v4 envs run on), gymnasium-robotics and this
package (`--no-deps`); `--venv DIR` makes one:

    python -m benchmarks.parity_v4 --venv /tmp/v4venv          # create it, then re-run inside it
    /tmp/v4venv/bin/python -m benchmarks.parity_v4 --rollouts 200
    /tmp/v4venv/bin/python -m benchmarks.parity_v4 --record tests/data/v4_reference.npz

(from the repository root). The same virtualenv runs `python -m tools.classic_starts`, which writes the
v4 start states the package ships.

For each task: the same seed in both envs, then the same uniform random actions in [-1, 1]^4
(plus the issue's two scripted patterns); the table gives the largest difference of the initial
observation and goal, and the p50 / p95 / max difference of the grip site and of the object
over all steps, how often both envs agree on `is_success`, and both envs' steps/s.
`--record` writes the v4 side of a few rollouts per task (small), which tests/test_parity_v4.py
replays on whatever mujoco the suite runs on.
"""

from __future__ import annotations

import argparse
import pathlib
import subprocess
import sys
import time

import numpy as np

from benchmarks._machine import machine_line

PAIRS = {
    "Reach-v2": "FetchReach-v4",
    "Push-v2": "FetchPush-v4",
    "PickPlace-v2": "FetchPickAndPlace-v4",
    "Slide-v2": "FetchSlide-v4",
}
STEPS = 50
RECORD_ROLLOUTS = 12
"""rollouts per task in the recorded reference: random actions, plus the two patterns."""
RECORD_RESETS = 50
"""seeds per task whose initial observation and goal the reference keeps."""


def make_venv(path: pathlib.Path) -> None:
    """A virtualenv with mujoco 3.11, gymnasium-robotics 1.4 and this package."""
    root = pathlib.Path(__file__).resolve().parent.parent
    subprocess.run([sys.executable, "-m", "venv", str(path)], check=True)
    pip = [str(path / "bin" / "python"), "-m", "pip", "install", "-q"]
    subprocess.run([*pip, "mujoco==3.11.0", "gymnasium-robotics==1.4.2", "h5py"], check=True)
    subprocess.run([*pip, "--no-deps", "-e", str(root)], check=True)
    print(f"made {path}; now run, from {root}: {path}/bin/python -m benchmarks.parity_v4 ...")


def action_patterns(rng: np.random.Generator, count: int) -> list[tuple[str, np.ndarray]]:
    """`count` uniform random action sequences, then full diagonal and full +x, each and back."""
    out = [("random", rng.uniform(-1.0, 1.0, size=(STEPS, 4)).astype(np.float32)) for _ in range(count)]
    half = STEPS // 2
    diagonal = np.zeros((STEPS, 4), np.float32)
    diagonal[:half, :3], diagonal[half:, :3] = 1.0, -1.0
    along_x = np.zeros((STEPS, 4), np.float32)
    along_x[:half, 0], along_x[half:, 0] = 1.0, -1.0
    return [*out, ("diagonal", diagonal), ("x", along_x)]


def present(env) -> np.ndarray:
    """[m] the grip site and the object (if any) computed from the present qpos: v4's observation
    reads positions from the start of the step's last physics step when its fingers are free."""
    import mujoco

    u = env.unwrapped
    scratch = getattr(u, "_parity_scratch", None)
    if scratch is None:
        scratch = u._parity_scratch = mujoco.MjData(u.model)
    scratch.qpos[:] = u.data.qpos
    scratch.mocap_pos[:], scratch.mocap_quat[:] = u.data.mocap_pos, u.data.mocap_quat
    mujoco.mj_kinematics(u.model, scratch)
    sites = ["robot0:grip"] + (["object0"] if mujoco.mj_name2id(u.model, mujoco.mjtObj.mjOBJ_SITE, "object0") >= 0
                               else [])
    return np.concatenate([scratch.site(name).xpos for name in sites])


def rollout(env, seed: int, actions: np.ndarray) -> dict[str, np.ndarray]:
    obs, _ = env.reset(seed=seed)
    observations, states, successes, rewards = [obs["observation"].copy()], [present(env)], [], []
    goal = obs["desired_goal"].copy()
    for action in actions:
        obs, reward, _, _, info = env.step(action)
        observations.append(obs["observation"].copy())
        states.append(present(env))
        successes.append(float(info["is_success"]))
        rewards.append(float(reward))
    return {"obs": np.array(observations), "present": np.array(states), "goal": goal,
            "success": np.array(successes), "reward": np.array(rewards)}


def steps_per_second(ours, theirs, rounds: int = 15) -> tuple[float, float]:
    """Both envs' steps/s through `gym.make`'s wrappers: the same 50 random actions from the same
    seed, one episode each in alternating rounds (so both see the same machine load); the fastest
    round of each."""
    actions = np.random.default_rng(0).uniform(-1, 1, size=(STEPS, 4)).astype(np.float32)
    best = [np.inf, np.inf]
    for r in range(rounds):
        for i, env in enumerate((ours, theirs)):
            env.reset(seed=r)
            start = time.perf_counter()
            for action in actions:
                env.step(action)
            best[i] = min(best[i], time.perf_counter() - start)
    return STEPS / best[0], STEPS / best[1]


def compare(ours_id: str, theirs_id: str, rollouts: int, first_seed: int) -> dict[str, object]:
    import gymnasium as gym

    ours, theirs = gym.make(ours_id), gym.make(theirs_id)
    has_object = ours.unwrapped.task.achieved != "grip_pos"
    rng = np.random.default_rng(first_seed)
    grip, obj, agree, init, goal, lag = [], [], [], 0.0, 0.0, []
    worst_pattern: dict[str, float] = {}
    for i, (kind, actions) in enumerate(action_patterns(rng, rollouts)):
        seed = first_seed + i
        a, b = rollout(ours, seed, actions), rollout(theirs, seed, actions)
        init = max(init, float(np.abs(a["obs"][0] - b["obs"][0]).max()))
        goal = max(goal, float(np.abs(a["goal"] - b["goal"]).max()))
        # The motion: grip site and object where each env's present state puts them.
        g = np.linalg.norm(a["present"][1:, :3] - b["present"][1:, :3], axis=1)
        grip.append(g)
        if has_object:
            obj.append(np.linalg.norm(a["present"][1:, 3:6] - b["present"][1:, 3:6], axis=1))
        # The observation: ours is of the present state; v4's may lag one physics step.
        lag.append(np.abs(a["obs"][1:] - b["obs"][1:]).max(axis=1))
        agree.append(a["success"] == b["success"])
        worst_pattern[kind] = max(worst_pattern.get(kind, 0.0), float(g.max()))
    grips = np.concatenate(grip)
    objs = np.concatenate(obj) if obj else np.zeros(1)
    return {
        "init": init, "goal": goal,
        "grip": np.percentile(grips, [50, 95, 100]), "object": np.percentile(objs, [50, 95, 100]),
        "has_object": has_object, "agree": float(np.concatenate(agree).mean()),
        "obs": np.percentile(np.concatenate(lag), [50, 95, 100]),
        "patterns": worst_pattern,
        "speed": steps_per_second(ours, theirs),
    }


def record(path: pathlib.Path, first_seed: int, rollouts: int = RECORD_ROLLOUTS) -> None:
    """The v4 side of a few rollouts and resets per task, for tests/test_parity_v4.py."""
    import gymnasium as gym
    import gymnasium_robotics
    import mujoco

    gym.register_envs(gymnasium_robotics)
    arrays: dict[str, np.ndarray] = {}
    for ours_id, theirs_id in PAIRS.items():
        env = gym.make(theirs_id)
        key = ours_id.split("-")[0]
        resets = [env.reset(seed=first_seed + s)[0] for s in range(RECORD_RESETS)]
        arrays[f"{key}/reset_seeds"] = np.arange(first_seed, first_seed + RECORD_RESETS)
        arrays[f"{key}/reset_observation"] = np.array([o["observation"] for o in resets])
        arrays[f"{key}/reset_goal"] = np.array([o["desired_goal"] for o in resets])
        patterns = action_patterns(np.random.default_rng(first_seed), rollouts - 2)
        runs = [rollout(env, first_seed + i, actions) for i, (_, actions) in enumerate(patterns)]
        arrays[f"{key}/seeds"] = np.arange(first_seed, first_seed + len(patterns))
        arrays[f"{key}/kinds"] = np.array([kind for kind, _ in patterns])
        arrays[f"{key}/actions"] = np.array([actions for _, actions in patterns])
        # The motion (grip site, object) from each present state, not the observation, which lags
        # one physics step in FetchPickAndPlace-v4. float32 keeps 0.1 um.
        arrays[f"{key}/positions"] = np.array([r["present"] for r in runs], dtype=np.float32)
        arrays[f"{key}/success"] = np.array([r["success"] for r in runs], dtype=np.uint8)
    arrays["versions"] = np.array([f"mujoco {mujoco.__version__}",
                                   f"gymnasium-robotics {gymnasium_robotics.__version__}"])
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    print(f"wrote {path} ({path.stat().st_size // 1024} KiB)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--venv", type=pathlib.Path, help="create a mujoco 3.11 virtualenv here and stop")
    parser.add_argument("--rollouts", type=int, default=200, help="random-action rollouts per task (200)")
    parser.add_argument("--first-seed", type=int, default=0, help="seed of the first rollout (0)")
    parser.add_argument("--only", nargs="*", default=list(PAIRS), help="task ids (all four)")
    parser.add_argument("--record", type=pathlib.Path, help="write the v4 reference rollouts here and stop")
    parser.add_argument("--record-rollouts", type=int, default=RECORD_ROLLOUTS,
                        help=f"rollouts per task --record keeps, the last two the patterns ({RECORD_ROLLOUTS})")
    args = parser.parse_args()
    if args.venv:
        make_venv(args.venv)
        return 0
    try:
        import gymnasium as gym
        import gymnasium_robotics

        import fetch  # noqa: F401  (registers the ids)
    except ImportError as error:
        print(f"parity_v4: {error}; make the environment with --venv DIR first", file=sys.stderr)
        return 2
    gym.register_envs(gymnasium_robotics)
    if args.record:
        record(args.record, args.first_seed, args.record_rollouts)
        return 0
    print(machine_line("gymnasium-robotics"))
    print(f"{args.rollouts} random rollouts of {STEPS} steps per task "
          "(+ full diagonal and full +x, each then back)\n")
    print("| ours | v4 | initial obs max diff | goal max diff | grip diff p50 / p95 / max [mm] | "
          "object diff p50 / p95 / max [mm] | observation diff p50 / p95 / max | is_success agree | "
          "worst grip diff: diagonal / +x [mm] | steps/s ours / v4 |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for ours_id in args.only:
        r = compare(ours_id, PAIRS[ours_id], args.rollouts, args.first_seed)
        grip = " / ".join(f"{v * 1000:.2f}" for v in r["grip"])  # type: ignore[union-attr]
        obj = (" / ".join(f"{v * 1000:.2f}" for v in r["object"])  # type: ignore[union-attr]
               if r["has_object"] else "-")
        pat = r["patterns"]
        lag = " / ".join(f"{v:.1e}" for v in r["obs"])  # type: ignore[union-attr]
        ours_speed, their_speed = r["speed"]  # type: ignore[misc]
        print(f"| `{ours_id}` | `{PAIRS[ours_id]}` | {r['init']:.1e} | {r['goal']:.1e} | {grip} | {obj} | {lag} | "
              f"{r['agree']:.1%} | {pat['diagonal'] * 1000:.2f} / {pat['x'] * 1000:.2f} | "  # type: ignore[index]
              f"{ours_speed:,.0f} / {their_speed:,.0f} ({ours_speed / their_speed:.2f}x) |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
