"""Physics under abuse: the worst contact penetration and object speed under extreme random actions.

Per task, `--steps` steps of random full-scale actions (each of a[0..3] is -1 or +1, held for a
random 1-5 steps so the hand really drives into things), a reset every 50 steps with a new seed.
After every step: the deepest contact (-dist over all contacts) and which geoms, and the fastest
free body (linear speed [m/s]). Prints a table; docs/results/bench_abuse.md holds the numbers.

`--contacts mujoco` gives our room's geoms MuJoCo's default contacts, as they were before the
room's stiff ones (fetch.scene.ROOM_SOLREF). `--experts N` adds the experts' success under the
chosen contacts; `--cost` times ordinary random steps both ways, alternating in one run.

    python -m benchmarks.bench_abuse --steps 10000 --experts 200
    python -m benchmarks.bench_abuse --steps 10000 --contacts mujoco --experts 200
    python -m benchmarks.bench_abuse --cost
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import mujoco
import numpy as np

import fetch
from benchmarks._machine import machine_line
from benchmarks.expert_success import evaluate
from fetch.scene import MUJOCO_SOLIMP, MUJOCO_SOLREF, ROOM_SOLIMP, ROOM_SOLREF

DEPTH_BAR, LAUNCH_BAR = 0.005, 1.0
"""Issue 20's bars: [m] the deepest contact, [m/s] the fastest launch."""


def room_geoms(env: gym.Env) -> list[int]:
    """The geoms built with the room's stiff contacts: everything in our room's tasks but the robot
    and the Box tasks' lid; none in the classic tasks' scenes."""
    m = env.unwrapped.model
    return [g for g in range(m.ngeom)
            if np.allclose(m.geom_solref[g], ROOM_SOLREF) and np.allclose(m.geom_solimp[g], ROOM_SOLIMP)]


def use_contacts(model: mujoco.MjModel, geoms: list[int], stiff: bool) -> None:
    """Give `geoms` the room's stiff contacts or MuJoCo's defaults (MjModel's solref and solimp are
    read every step, so the defaults make the old model)."""
    model.geom_solref[geoms] = ROOM_SOLREF if stiff else MUJOCO_SOLREF
    model.geom_solimp[geoms] = ROOM_SOLIMP if stiff else MUJOCO_SOLIMP


def soften(env: gym.Env) -> None:
    """Give the room's geoms MuJoCo's default contacts, as before."""
    use_contacts(env.unwrapped.model, room_geoms(env), stiff=False)


def abuse(env_id: str, steps: int, seed: int, contacts: str = "model") -> dict[str, object]:
    env = gym.make(env_id, max_episode_steps=10**9)
    u = env.unwrapped
    if contacts == "mujoco":
        soften(env)
    return measure(u.model, u.data, lambda episode_seed: env.reset(seed=episode_seed), env.step, steps, seed)


class Watch:
    """The worst penetration, object speed and launch over the steps it is shown, with where and when,
    and how many steps broke the bars."""

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        self.m, self.d = m, d
        self.free = [j for j in range(m.njnt) if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)]
        self.robot = {b for b in range(m.nbody) if m.body(b).name.startswith("robot0:")}
        self.grip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "robot0:grip")
        self.grip_vel = np.zeros(6)
        self.depth, self.depth_where, self.speed, self.speed_where = 0.0, "", 0.0, ""
        self.launch, self.launch_where = 0.0, ""
        self.deep_steps = self.launch_steps = self.steps = 0
        self.touched: set[int] = set()  # free bodies touching the robot after the previous step

    def episode(self) -> None:
        """A new episode starts: nothing touches the robot yet."""
        self.touched = set()

    def after_step(self, when: str) -> None:
        """Look at the state a step left; `when` says which step, for the report."""
        m, d = self.m, self.d
        self.steps += 1
        if d.ncon:
            i = int(np.argmin(d.contact.dist[: d.ncon]))
            depth = -float(d.contact.dist[i])
            self.deep_steps += depth > DEPTH_BAR
            if depth > self.depth:
                names = [m.geom(g).name or m.body(m.geom_bodyid[g]).name
                         for g in (int(d.contact.geom1[i]), int(d.contact.geom2[i]))]
                self.depth, self.depth_where = depth, f"{names[0]} / {names[1]} ({when})"
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, self.grip, self.grip_vel, 0)
        launched = False
        for j in self.free:
            speed = float(np.linalg.norm(d.qvel[m.jnt_dofadr[j]:m.jnt_dofadr[j] + 3]))
            where = f"{m.body(m.jnt_bodyid[j]).name} ({when})"
            if speed > self.speed:
                self.speed, self.speed_where = speed, where
            if j in self.touched:
                launch = speed - float(np.linalg.norm(self.grip_vel[3:]))
                launched |= launch > LAUNCH_BAR
                if launch > self.launch:
                    self.launch, self.launch_where = launch, where
        self.launch_steps += launched
        bodies = m.geom_bodyid[d.contact.geom1[: d.ncon]].tolist(), m.geom_bodyid[d.contact.geom2[: d.ncon]].tolist()
        self.touched = {j for a, b in zip(*bodies, strict=True) for j in self.free
                        if (a == m.jnt_bodyid[j] and b in self.robot) or (b == m.jnt_bodyid[j] and a in self.robot)}

    def result(self, seconds: float) -> dict[str, object]:
        return {"depth": self.depth, "depth_where": self.depth_where, "speed": self.speed,
                "speed_where": self.speed_where, "launch": self.launch, "launch_where": self.launch_where,
                "deep_steps": self.deep_steps, "launch_steps": self.launch_steps, "steps": self.steps,
                "steps_per_s": self.steps / seconds}


def measure(m: mujoco.MjModel, d: mujoco.MjData, reset: Callable[[int], object],
            step_with: Callable[[np.ndarray], object], steps: int, seed: int) -> dict[str, object]:
    """The abuse on any model that `reset(seed)` starts and `step_with(action)` steps (MjData `d`):
    the worst penetration, object speed and launch, with where and when."""
    watch = Watch(m, d)
    rng = np.random.default_rng(seed)
    action = np.zeros(4, np.float32)
    hold = 0
    start = time.perf_counter()
    episode_seed = seed
    for step in range(steps):
        if step % 50 == 0:
            episode_seed = int(rng.integers(2**31))
            reset(episode_seed)
            watch.episode()
        if hold == 0:
            action = rng.choice([-1.0, 1.0], size=4).astype(np.float32)
            hold = int(rng.integers(1, 6))
        hold -= 1
        step_with(action)
        watch.after_step(f"seed {episode_seed}, step {step % 50}")
    return watch.result(time.perf_counter() - start)


def in_use(env_id: str, seeds: int, noise: float) -> dict[str, object]:
    """The same figures in the expert's own episodes (seeds 0..seeds-1, Gaussian action noise of std
    `noise`, as expert_success.py runs them): what the physics does in the use it is made for."""
    watches: list[Watch] = []

    def watch(seed: int, step: int) -> None:
        if step == 0:
            watches[0].episode()
        watches[0].after_step(f"seed {seed}, step {step}")

    start = time.perf_counter()
    evaluate(env_id, seeds, noise, prepare=lambda env: watches.append(Watch(env.unwrapped.model, env.unwrapped.data)),
             after_step=watch)
    return watches[0].result(time.perf_counter() - start)


def cost(env_id: str, steps: int, rounds: int = 5) -> float:
    """Steps/s with the room's stiff contacts over steps/s with MuJoCo's defaults: ordinary uniform
    random actions, the two alternating in `rounds` rounds on one env; the median ratio."""
    env = gym.make(env_id, max_episode_steps=10**9)
    m = env.unwrapped.model
    geoms = room_geoms(env)
    ratios = []
    for r in range(rounds):
        rates = {}
        for stiff in (True, False) if r % 2 else (False, True):
            use_contacts(m, geoms, stiff)
            actions = np.random.default_rng(r).uniform(-1.0, 1.0, size=(steps, 4)).astype(np.float32)
            start = time.perf_counter()
            for step in range(steps):
                if step % 50 == 0:
                    env.reset(seed=r * steps + step)
                env.step(actions[step])
            rates[stiff] = steps / (time.perf_counter() - start)
        ratios.append(rates[True] / rates[False])
    return float(np.median(ratios))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=10000, help="abusive steps per task (10000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the action and reset draws (0)")
    parser.add_argument("--only", nargs="*", default=list(fetch.ENV_IDS), help="task ids (all)")
    parser.add_argument("--contacts", choices=("model", "mujoco"), default="model",
                        help="the contacts as the model has them (model), or MuJoCo's defaults on the "
                             "room's geoms, as before the room's stiff contacts (mujoco)")
    parser.add_argument("--cost", action="store_true",
                        help="instead: steps/s with the room's stiff contacts over steps/s with MuJoCo's defaults")
    parser.add_argument("--experts", type=int, default=0, metavar="N",
                        help="also run each task's expert on seeds 0..N-1, plain and with action noise 0.1")
    parser.add_argument("--in-use", type=int, default=0, metavar="N",
                        help="instead: the same figures in each task's expert episodes, seeds 0..N-1, plain "
                             "and with action noise 0.1")
    args = parser.parse_args()
    if args.in_use:
        print(machine_line())
        print(f"the experts' episodes, seeds 0-{args.in_use - 1}\n")
        print("| task | action noise | worst penetration [mm] | where | steps > 5 mm | fastest launch [m/s] | which "
              "| steps > 1 m/s | steps |")
        print("|---|---|---|---|---|---|---|---|---|")
        for env_id in args.only:
            for noise in (0.0, 0.1):
                r = in_use(env_id, args.in_use, noise)
                print(f"| `{env_id}` | {noise} | {r['depth'] * 1000:.1f} | {r['depth_where'] or '-'} | "
                      f"{r['deep_steps']} | {r['launch']:.2f} | {r['launch_where'] or '-'} | {r['launch_steps']} | "
                      f"{r['steps']} |", flush=True)
        return
    # Only our room's tasks have two contact models to compare.
    only = [e for e in args.only if (args.contacts == "model" and not args.cost) or room_geoms(gym.make(e))]
    if args.cost:
        print(machine_line())
        print("5 rounds of 1000 uniform random steps each way\n")
        print("| task | steps/s stiff / MuJoCo's default contacts (median of 5) |\n|---|---|")
        for env_id in only:
            print(f"| `{env_id}` | {cost(env_id, 1000):.3f} |", flush=True)
        return
    print(machine_line())
    print(f"{args.steps} abusive steps per task, seed {args.seed}, "
          f"{args.contacts} contacts\n")
    print("| task | worst penetration [mm] | where | steps > 5 mm | fastest object [m/s] | which "
          "| fastest launch [m/s] | which | steps > 1 m/s | steps/s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for env_id in only:
        r = abuse(env_id, args.steps, args.seed, args.contacts)
        print(f"| `{env_id}` | {r['depth'] * 1000:.1f} | {r['depth_where']} | {r['deep_steps']} | {r['speed']:.2f} | "
              f"{r['speed_where'] or '-'} | {r['launch']:.2f} | {r['launch_where'] or '-'} | {r['launch_steps']} | "
              f"{r['steps_per_s']:,.0f} |", flush=True)
    prepare = soften if args.contacts == "mujoco" else None
    if args.experts:
        print(f"\n| task | expert, seeds 0-{args.experts - 1} | with action noise 0.1 | first success: mean step |")
        print("|---|---|---|---|")
        for env_id in only:
            plain = evaluate(env_id, args.experts, 0.0, prepare=prepare)
            noisy = evaluate(env_id, args.experts, 0.1, prepare=prepare)
            print(f"| `{env_id}` | {plain['success']:.1%} | {noisy['success']:.1%} | {plain['first_mean']:.1f} |",
                  flush=True)


if __name__ == "__main__":
    main()
