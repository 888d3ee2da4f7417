"""Physics under abuse: the worst contact penetration and object speed under extreme random actions.

Per task, `--steps` steps of random full-scale actions (each of a[0..3] is -1 or +1, held for a
random 1-5 steps so the hand really drives into things), a reset every 50 steps with a new seed.
After every step: the deepest contact (-dist over all contacts) and which geoms, and the fastest
free body (linear speed [m/s]). Prints a table; docs/benchmarks.md holds the numbers.

    python benchmarks/bench_abuse.py --steps 10000
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import mujoco
import numpy as np

import fetch


def abuse(env_id: str, steps: int, seed: int) -> dict[str, object]:
    env = gym.make(env_id, max_episode_steps=10**9)
    u = env.unwrapped
    m, d = u.model, u.data
    free = [j for j in range(m.njnt) if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)]
    rng = np.random.default_rng(seed)
    worst_depth, depth_where, worst_speed, speed_where = 0.0, "", 0.0, ""
    action = np.zeros(4, np.float32)
    hold = 0
    start = time.perf_counter()
    episode_seed = seed
    for step in range(steps):
        if step % 50 == 0:
            episode_seed = int(rng.integers(2**31))
            env.reset(seed=episode_seed)
        if hold == 0:
            action = rng.choice([-1.0, 1.0], size=4).astype(np.float32)
            hold = int(rng.integers(1, 6))
        hold -= 1
        env.step(action)
        if d.ncon:
            i = int(np.argmin(d.contact.dist[: d.ncon]))
            depth = -float(d.contact.dist[i])
            if depth > worst_depth:
                g1, g2 = int(d.contact.geom1[i]), int(d.contact.geom2[i])
                worst_depth = depth
                names = [m.geom(g).name or m.body(m.geom_bodyid[g]).name for g in (g1, g2)]
                depth_where = f"{names[0]} / {names[1]} (seed {episode_seed}, step {step % 50})"
        for j in free:
            speed = float(np.linalg.norm(d.qvel[m.jnt_dofadr[j]:m.jnt_dofadr[j] + 3]))
            if speed > worst_speed:
                worst_speed = speed
                speed_where = f"{m.body(m.jnt_bodyid[j]).name} (seed {episode_seed}, step {step % 50})"
    return {"depth": worst_depth, "depth_where": depth_where, "speed": worst_speed, "speed_where": speed_where,
            "steps_per_s": steps / (time.perf_counter() - start)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=10000, help="abusive steps per task (10000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the action and reset draws (0)")
    parser.add_argument("--only", nargs="*", default=list(fetch.ENV_IDS), help="task ids (all)")
    args = parser.parse_args()
    print(f"mujoco {mujoco.__version__}; {args.steps} abusive steps per task, seed {args.seed}\n")
    print("| task | worst penetration [mm] | where | fastest object [m/s] | which | steps/s |")
    print("|---|---|---|---|---|---|")
    for env_id in args.only:
        r = abuse(env_id, args.steps, args.seed)
        print(f"| `{env_id}` | {r['depth'] * 1000:.1f} | {r['depth_where']} | {r['speed']:.2f} | "
              f"{r['speed_where'] or '-'} | {r['steps_per_s']:,.0f} |", flush=True)


if __name__ == "__main__":
    main()
