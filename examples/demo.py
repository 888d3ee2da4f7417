"""The install test: make every task, reset it, take random steps and render offscreen; one line per task."""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import fetch  # noqa: F401  (registers the ids)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=10, help="random steps per task")
    parser.add_argument("--render", choices=["rgb_array", "human", "none"], default="rgb_array",
                        help="rgb_array renders offscreen (no display needed); human opens a window")
    args = parser.parse_args()
    render_mode = None if args.render == "none" else args.render
    failures = 0
    for env_id in fetch.ENV_IDS:
        try:
            start = time.perf_counter()
            env = gym.make(env_id, render_mode=render_mode)
            obs, info = env.reset(seed=0)
            made = time.perf_counter() - start
            frame = None
            for _ in range(args.steps):
                obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
                frame = env.render() if render_mode else None
            env.close()
            shown = f"frame {frame.shape}" if isinstance(frame, np.ndarray) else args.render
            print(f"ok   {env_id:16s} obs {obs['observation'].shape[0]:2d}  goal {np.round(obs['desired_goal'], 3)}"
                  f"  {args.steps} steps  {shown}  ({made:.2f} s to make and reset)")
        except Exception as exc:  # report every task, then fail
            failures += 1
            print(f"FAIL {env_id:16s} {type(exc).__name__}: {exc}")
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
