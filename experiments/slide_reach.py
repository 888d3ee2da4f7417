"""Which Slide-v2 goals some plan of one or two strikes reaches in 50 steps: a search in simulation.

For each seed, every plan of one strike (line x, the two diagonals, +-y; the expert's action size for
the goal's distance along the line times 0.85..1.15, and 1) and of two strikes (the first along x,
the diagonal towards the goal or y towards the goal, action size 0.3..1; the second along x or a
diagonal, sized as a single strike) is run from the start with the Slide expert's own line-up and
strike (`fetch.experts.slide.Slide`), the second strike branching from a copy of the env taken when
the first ends. A seed no plan of the family reaches is counted unreachable *by this family*: the
search bounds what two strikes can do, not what any policy can. The expert itself is also run on
every seed, plain and under action noise 0.1, and its rate on the seeds the family reaches printed.

    .venv/bin/python -m experiments.slide_reach --seeds 100 --first-seed 0     # ~10 min a process
    .venv/bin/python -m experiments.slide_reach --seeds 100 --first-seed 100

Seeds 0-199 (mujoco 4.0.0): one strike reaches 34 %, two strikes 57.5 %, neither 8.5 % (seeds 0,
18, 56, 61, 85, 93, 107, 112, 122, 132, 133, 148, 159, 165, 168, 179, 180: goals far out and to the
side, 0.6-0.8 m from the puck; a strike carries the puck at most ~0.7 m along x or ~0.4 m per
axis on the diagonal from x <= 1.15 m, less further out or to the side, and none past x ~ 1.39
m). The expert wins 95.1 % of the 183 seeds the family reaches, and 6 of the 17 it does not (it
plans again after each strike, and may strike three times).
"""

from __future__ import annotations

import argparse
import copy
import pickle
import time

import gymnasium as gym
import numpy as np

import fetch  # noqa: F401  (registers the ids)
from fetch.experts import make_expert
from fetch.experts.base import Stage
from tools.slide_strikes import Forced

SIZES = (0.3, 0.45, 0.6, 0.75, 0.9, 1.0)
"""Action sizes of a first strike."""
SCALES = (-0.85, -0.9, -0.95, -1.0, -1.05, -1.1, -1.15, 1.0)
"""A strike aimed at the goal: the expert's size (from its strike table) times 0.85..1.15, and 1."""
HORIZON = 50


def _finish(env: gym.Env, expert: Forced, obs: dict, steps: int) -> bool:
    info: dict = {}
    for _ in range(steps):
        obs, _, _, _, info = env.step(expert(obs))
    return bool(info.get("is_success", False))


def search(seed: int) -> tuple[str, int]:
    """('one' | 'two' | 'none', rollouts) for the seed's start and goal."""
    env = gym.make("Slide-v2").unwrapped
    layout = env.observation_layout
    obs, _ = env.reset(seed=seed)
    puck = obs["observation"][layout["object_pos"]][:2]
    dy = float(obs["desired_goal"][1] - puck[1])
    sy = 1.0 if dy >= 0 else -1.0
    start = pickle.dumps(env)
    rollouts = 0
    for line in ((1.0, 0.0), (1.0, 1.0), (1.0, -1.0), (0.0, 1.0), (0.0, -1.0)):
        for size in SCALES:
            run = pickle.loads(start)
            expert = Forced(layout, [(line, size)])
            rollouts += 1
            if _finish(run, expert, obs, HORIZON):
                return "one", rollouts
    for first in ((1.0, 0.0), (1.0, sy), (0.0, sy)):
        for size in SIZES:
            run = pickle.loads(start)
            expert = Forced(layout, [(first, size), ((1.0, 0.0), 0.0)])
            current, steps = obs, 0
            while steps < HORIZON and not (expert.stage is Stage.WATCH and expert.pushes == 1):
                current = run.step(expert(current))[0]
                steps += 1
            branch_env, branch_expert = pickle.dumps(run), copy.deepcopy(expert)
            for second in ((1.0, 0.0), (1.0, sy), (1.0, -sy)):
                for size2 in SCALES:
                    run2 = pickle.loads(branch_env)
                    expert2 = copy.deepcopy(branch_expert)
                    expert2.queue = [(second, size2)]
                    rollouts += 1
                    if _finish(run2, expert2, current, HORIZON - steps):
                        return "two", rollouts
    return "none", rollouts


def expert_wins(seed: int, noise: float) -> bool:
    """Whether the Slide expert itself succeeds on `seed` at the last step (action noise of std
    `noise`, drawn from a generator seeded by the seed)."""
    env = gym.make("Slide-v2")
    expert = make_expert(env)  # with its twin, as shipped
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    info: dict = {}
    for _ in range(HORIZON):
        action = expert(obs)
        if noise:
            action = action + rng.normal(0.0, noise, size=4).astype(np.float32)
        obs, _, _, _, info = env.step(action)
    return bool(info["is_success"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=200)
    parser.add_argument("--first-seed", type=int, default=0)
    args = parser.parse_args()
    counts = {"one": 0, "two": 0, "none": 0}
    unreachable = []
    wins: dict[float, list[tuple[bool, bool]]] = {0.0: [], 0.1: []}  # noise: (reachable, expert won)
    start = time.perf_counter()
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        verdict, rollouts = search(seed)
        counts[verdict] += 1
        if verdict == "none":
            unreachable.append(seed)
        for noise, outcomes in wins.items():
            outcomes.append((verdict != "none", expert_wins(seed, noise)))
        print(f"seed {seed}: {verdict} ({rollouts} rollouts); the expert "
              f"{'wins' if wins[0.0][-1][1] else 'fails'}", flush=True)
    n = args.seeds
    print(f"\n{n} seeds in {time.perf_counter() - start:.0f} s: one strike {counts['one'] / n:.1%}, "
          f"two strikes {counts['two'] / n:.1%}, neither {counts['none'] / n:.1%}")
    print("unreachable by the family:", unreachable)
    for noise, outcomes in wins.items():
        reached = [won for reachable, won in outcomes if reachable]
        beyond = [won for reachable, won in outcomes if not reachable]
        print(f"the expert{f' under action noise {noise}' if noise else ''}: {np.mean([w for _, w in outcomes]):.1%} "
              f"of all, {np.mean(reached) if reached else float('nan'):.1%} of the {len(reached)} the family "
              f"reaches; wins {sum(beyond)} of the {len(beyond)} it does not")


if __name__ == "__main__":
    main()
