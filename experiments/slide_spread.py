"""How far Slide strikes land under action noise, against the same strike without: what aiming by striking can rely on.

The puck at rest in front of the shoulder and 0.15 m to the side; TRIALS strikes of each size along x
and the diagonal, with Gaussian noise on every action (line-up and strike, as
benchmarks/expert_success.py adds it). Its result (docs/results/expert_success.md, "Why no striking expert
reaches 80 % under action noise 0.1") is why that bar was left unmet.

    .venv/bin/python -m experiments.slide_spread --trials 100        # ~6 min
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

from benchmarks._machine import machine_line
from fetch.experts.strikes import CENTRE_Y
from tools.slide_strikes import strike

SPREAD_FROM = ((1.1, CENTRE_Y), (1.2, CENTRE_Y + 0.15))
"""[m] where the puck rests before the strikes `spread` measures: in front of the shoulder and out to the side."""
SPREAD_SIZES = (0.3, 0.5, 0.7, 0.9)


def spread(trials: int, noise: float, tolerance: float = 0.05) -> None:
    """Print how far strikes of each size land from where the same strike lands without noise,
    under action noise `noise`: what a policy that aims by striking can rely on."""
    env = gym.make("Slide-v2").unwrapped
    rng = np.random.default_rng(0)
    print(machine_line())
    print(f"{trials} strikes per row under action noise {noise}; displacements against the same strike "
          "without noise\n")
    print(f"| puck at [m] | line | size | without noise [cm] | along: mean / std [cm] | across: std [cm] "
          f"| within {100 * tolerance:.0f} cm of it |")
    print("|---|---|---|---|---|---|---|")
    for xy in SPREAD_FROM:
        for line in ((1.0, 0.0), (1.0, 1.0)):
            unit = np.asarray(line) / np.hypot(*line)
            normal = np.array([-unit[1], unit[0]])
            for size in SPREAD_SIZES:
                plain = strike(env, xy, line, size)
                noisy = [strike(env, xy, line, size, noise, rng) for _ in range(trials)]
                if plain is None:
                    continue
                moved = np.array([m for m in noisy if m is not None])
                along, across = moved @ unit, moved @ normal
                within = np.linalg.norm(moved - plain, axis=1) < tolerance
                print(f"| ({xy[0]:.2f}, {xy[1]:.2f}) | {'x' if line[1] == 0 else 'diagonal'} | {size} "
                      f"| {100 * float(plain @ unit):.1f} | {100 * along.mean():.1f} / {100 * along.std():.1f} "
                      f"| {100 * across.std():.1f} | {within.sum() / trials:.0%} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=100, help="noisy strikes per row (100)")
    parser.add_argument("--noise", type=float, default=0.1, help="the action noise's std (0.1)")
    args = parser.parse_args()
    spread(args.trials, args.noise)


if __name__ == "__main__":
    main()
