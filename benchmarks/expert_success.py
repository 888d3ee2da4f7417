"""Success rate of every task's scripted expert: the standard Fetch rate (is_success at the last step)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import fetch
from fetch.experts import make_expert


def evaluate(env_id: str, seeds: int, noise: float, first_seed: int = 0,
             prepare: Callable[[gym.Env], None] | None = None,
             after_step: Callable[[int, int], None] | None = None) -> dict[str, float]:
    """Run `seeds` episodes of the registered horizon, from seed `first_seed` on; Gaussian action
    noise of std `noise`. `prepare` may change the env first (bench_abuse.py's contact trial);
    `after_step(seed, step)` looks at each step's result (step 0 is an episode's first)."""
    env = gym.make(env_id)
    if prepare is not None:
        prepare(env)
    expert = make_expert(env)
    rng = np.random.default_rng(12345)
    finals, firsts = [], []
    for seed in range(first_seed, first_seed + seeds):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        first, done, info = None, False, {}
        step = 0
        while not done:
            action = expert(obs)
            if noise:
                action = action + rng.normal(0.0, noise, size=4).astype(np.float32)
            obs, _, terminated, truncated, info = env.step(action)
            if after_step is not None:
                after_step(seed, step)
            step += 1
            if first is None and info["is_success"]:
                first = step
            done = terminated or truncated
        finals.append(info["is_success"])
        if first is not None:
            firsts.append(first)
    return {
        "success": float(np.mean(finals)),
        "first_mean": float(np.mean(firsts)) if firsts else float("nan"),
        "first_p95": float(np.percentile(firsts, 95)) if firsts else float("nan"),
        "horizon": float(env.spec.max_episode_steps),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=200)
    parser.add_argument("--first-seed", type=int, default=0,
                        help="start from this seed (e.g. 1000: seeds no expert was tuned on)")
    parser.add_argument("--noise", type=float, nargs="*", default=[0.0, 0.1],
                        help="action-noise stds to evaluate (0 = the plain expert)")
    parser.add_argument("--only", nargs="*", default=list(fetch.ENV_IDS))
    args = parser.parse_args()
    header = "| task | horizon | " + " | ".join(
        f"success (noise {n})" for n in args.noise) + " | first success: mean | p95 |"
    print(f"{args.seeds} seeds per task from seed {args.first_seed}; "
          "success = is_success at the last step of the horizon\n")
    print(header)
    print("|" + "---|" * (header.count("|") - 1))
    for env_id in args.only:
        start = time.perf_counter()
        results = [evaluate(env_id, args.seeds, n, args.first_seed) for n in args.noise]
        plain = results[0]
        rates = " | ".join(f"{r['success']:.1%}" for r in results)
        print(f"| `{env_id}` | {plain['horizon']:.0f} | {rates} | {plain['first_mean']:.1f} | "
              f"{plain['first_p95']:.0f} |   <!-- {time.perf_counter() - start:.0f} s -->", flush=True)


if __name__ == "__main__":
    main()
