"""A correction round with a stand-in corrector: what `collect --device takeover` and `train --from` buy.

    python benchmarks/corrections.py --env Bin-pick-v2 --dir /tmp/corr [--demos 100] [--attempts 20]

Each stage is skipped when its output is already in --dir, so an interrupted run goes on where it stopped:

1. `demos`: --demos expert demos (DART noise, as `collect --device expert` records them), seeds 0...
2. `base`: `gym-fetch train demos` with the task's defaults; evaluated on 100 unseen seeds.
3. `corrected`: --attempts attempts (seeds 50000...) where the base policy drives and the stand-in
   corrector watches: when the policy stalls (the hand moved < 1 cm over the last `STALL` steps, the task
   not done) or has used up the expert's usual time without success, it takes over (`Command.touched`, as
   a pad past its dead zone), drives as the expert would (a fresh `fetch.experts` expert, its clean
   actions) for `DRIVE` steps or until success, and lets go (the device hands back after 0.5 s).
4. `fixed`: `gym-fetch train demos corrected --from base`, evaluated on the same 100 seeds.
5. `plain` (the comparison): as many more expert demos as corrected attempts (seeds 60000...), then
   `gym-fetch train demos more --from base`, evaluated likewise.

It prints each stage's time and a table. The stand-in reads the simulator's state, as the expert does; a
person reads the window. It drives the takeover device directly, not through SDL (the pad path is what
tests/test_takeover.py checks).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import time
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

import fetch
from fetch.cli import main as gym_fetch
from fetch.experts import make_expert
from fetch.learn.device import PolicyDevice
from fetch.learn.takeover import TakeoverDevice
from fetch.teleop.devices import Command
from fetch.teleop.session import CollectConfig, Session

STALL = 12
"""[steps] a hand that moved less than 1 cm over this many steps, the task not done, has stalled."""
DRIVE = 20
"""[steps] how long the stand-in drives once it has taken over (unless the task is done first)."""
CORRECTION_SEEDS, PLAIN_SEEDS = 50_000, 60_000


class StandInCorrector:
    """A person's side of `TakeoverDevice`: watches the policy drive, takes over when it stalls or runs out of
    the expert's time, drives as the expert would, lets go."""

    name = "standin"

    def __init__(self, env: gym.Env, patience: int) -> None:
        self.expert = make_expert(env)
        self.patience = patience
        self.reset()

    def reset(self) -> None:
        self.tick, self.driving, self.grips, self.takeovers = 0, 0, [], 0

    def gripper_from(self, action: np.ndarray | None) -> None:
        pass

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        self.tick += 1
        grip = np.asarray(obs["observation"])[:3].copy()
        self.grips.append(grip)
        done = float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"])) < 0.05
        if self.driving:
            self.driving -= 1
            if done:
                self.driving = 0
            return Command(self.expert(obs), touched=True)
        stalled = len(self.grips) > STALL and np.linalg.norm(grip - self.grips[-STALL - 1]) < 0.01
        late = self.tick > self.patience and self.tick % self.patience == 1
        if not done and (stalled or late):
            self.expert.reset()
            self.driving, self.grips = DRIVE - 1, []
            self.takeovers += 1
            return Command(self.expert(obs), touched=True)
        return Command(np.zeros(4, np.float32))

    def close(self) -> None:
        pass


def timed(what: str, times: dict[str, float], run: Any) -> Any:
    start = time.perf_counter()
    out = run()
    times[what] = time.perf_counter() - start
    return out


def evaluate(run: pathlib.Path, episodes: int) -> dict[str, Any]:
    report = run / "eval.json"
    if not report.exists():
        assert gym_fetch(["eval", str(run), "--episodes", str(episodes), "--json", str(report)]) == 0
    return json.loads(report.read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Bin-pick-v2")
    parser.add_argument("--dir", required=True)
    parser.add_argument("--demos", type=int, default=100)
    parser.add_argument("--attempts", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--weight", type=int, default=None, help="--correction-weight (default: train's)")
    args = parser.parse_args()
    root = pathlib.Path(args.dir)
    root.mkdir(parents=True, exist_ok=True)
    times: dict[str, float] = {}
    env_id = args.env
    horizon = gym.spec(env_id).max_episode_steps or 50

    def collect_expert(out: pathlib.Path, episodes: int, seed: int) -> None:
        if not out.exists():
            assert gym_fetch(["collect", "--env", env_id, "--device", "expert", "--episodes", str(episodes),
                              "--render", "none", "--seed", str(seed), "--out", str(out)]) == 0

    def train(out: pathlib.Path, *data: pathlib.Path, start: pathlib.Path | None = None) -> None:
        if not (out / "eval.json").exists():  # train resumes a stopped run, and leaves a finished one
            extra = ["--from", str(start)] if start else []
            extra += ["--correction-weight", str(args.weight)] if args.weight and start else []
            assert gym_fetch(["train", *map(str, data), "--out", str(out), *extra]) == 0

    timed("demos", times, lambda: collect_expert(root / "demos", args.demos, 0))
    timed("train base", times, lambda: train(root / "base", root / "demos"))
    base = timed("eval base", times, lambda: evaluate(root / "base", args.episodes))

    corrected = root / "corrected"
    summary: dict[str, Any] = {}

    def correct() -> None:
        if corrected.exists():
            return
        env = gym.make(env_id, max_episode_steps=3 * horizon)
        person = StandInCorrector(env, patience=horizon)
        device = TakeoverDevice(PolicyDevice(env, root / "base"), person)
        config = CollectConfig(env_id=env_id, out=str(corrected), episodes=args.attempts, max_steps=3 * horizon,
                               device="takeover", render="none", control_hz=0, keep_failures=True,
                               seed=CORRECTION_SEEDS)
        result = Session(config, device, env=env, log=lambda _: None).run()
        summary.update(attempts=len(result.attempts), succeeded=sum(a.success for a in result.attempts))

    timed("collect corrections", times, correct)
    timed("train fixed", times, lambda: train(root / "fixed", root / "demos", corrected, start=root / "base"))
    fixed = timed("eval fixed", times, lambda: evaluate(root / "fixed", args.episodes))
    timed("plain demos", times, lambda: collect_expert(root / "more", args.attempts, PLAIN_SEEDS))
    timed("train plain", times, lambda: train(root / "plain", root / "demos", root / "more", start=root / "base"))
    plain = timed("eval plain", times, lambda: evaluate(root / "plain", args.episodes))

    from fetch.dataset import open_dataset
    from fetch.dataset.reader import summarize

    with open_dataset(corrected) as ds:
        demos, takeovers, person, steps = summarize(ds).corrections
    print(f"machine: {platform.platform()}, {os.cpu_count()} cores; python {platform.python_version()}, fetch "
          f"{fetch.__version__}, mujoco {mujoco.__version__}; {env_id}, {args.demos} expert demos, "
          f"{args.attempts} corrected attempts ({demos} with takeovers, {takeovers} takeovers, {person} of "
          f"{steps} steps by the stand-in), {args.episodes} evaluation episodes\n")
    print("| policy | success | 95 % interval |\n|---|---|---|")
    for name, result in (("base (expert demos)", base), ("base + corrections (--from base)", fixed),
                         (f"base + {args.attempts} more expert demos (--from base)", plain)):
        low, high = result["ci95"]
        print(f"| {name} | {100 * result['success_rate']:.0f} % | {100 * low:.0f}-{100 * high:.0f} % |")
    round_time = sum(times.get(k, 0.0) for k in ("collect corrections", "train fixed", "eval fixed"))
    print("\n" + ", ".join(f"{k} {v:.0f} s" for k, v in times.items()) + f"; the correction round {round_time:.0f} s")


if __name__ == "__main__":
    main()
