"""A correction round with a stand-in corrector: what `collect --device takeover` and `train --from` buy.

    python -m benchmarks.corrections --env Bin-pick-v2 --dir /tmp/corr [--demos 100] [--attempts 20]
        [--style person [--seed 100]]
    python -m benchmarks.corrections --env Bin-place-v2 --style person --mission M/Bin-place-v2/person --dir /tmp/corr
        [--starts tight]

Each stage is skipped when its output is already in --dir, so an interrupted run goes on where it stopped:

1. `demos`: --demos expert demos (DART noise, as `collect --device expert` records them), seeds 0...; with
   `--style`, --demos pad demos by that stand-in operator through SDL's virtual pad (`benchmarks.mission`'s
   teleop, collection seed `--seed`): a person's few demos, no `generate`.
2. `base`: `gym-fetch train demos` with the task's defaults; evaluated on --episodes unseen seeds.
3. `corrected`: --attempts attempts (seeds 50000...) where the base policy drives and the stand-in
   corrector watches: when the policy stalls (the hand moved < 1 cm over the last `STALL` steps, the task
   not done), drifts (`--drift`: the hand moved against where the expert would move it, or the fingers
   stayed far from where it would have them, for `DRIFT` steps running) or has used up the expert's
   usual time without success, it takes over (`Command.touched`, as a pad past its dead zone), drives as
   the expert would (a `fetch.experts` expert, its clean actions) for `DRIVE` steps or until success,
   and lets go (the device hands back after 0.5 s).
4. `fixed`: `gym-fetch train demos corrected --from base`, evaluated on the same seeds.
5. `plain` (the comparison): as many more demos as corrected attempts, of the same kind (seeds 60000...), then
   `gym-fetch train demos more --from base`, evaluated likewise.

With `--mission M` (a `benchmarks.mission` folder, state or cameras) the round starts from what a user has after
the whole path: the base is M's policy (`M/run`, not trained again) and its training data M's generated demos,
which `fixed` and `plain` learn from again beside the corrections or the `--style` stand-in's more pad demos. For
a camera policy the corrections record the cameras it sees and the more pad demos get them from `render-obs`, at
its image size and quality.

With `--starts tight` the corrected attempts and the more pad (or expert) demos start only where the object
stands close beside something (`collect --starts tight`): where a Bin task's policy fails most.

It prints each stage's time and a table. The stand-in reads the simulator's state, as the expert does; a
person reads the window. It drives the takeover device directly, not through SDL (the pad path is what
tests/test_takeover.py checks).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import shlex
import time
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

import fetch.learn
from benchmarks._machine import machine_line
from benchmarks.mission import teleop, training_data
from fetch.cli import main as gym_fetch
from fetch.experts import make_expert
from fetch.learn.device import PolicyDevice
from fetch.learn.evaluate import EVAL_SEED_START
from fetch.learn.takeover import TakeoverDevice
from fetch.teleop.devices import Command
from fetch.teleop.session import CollectConfig, Session

STALL = 12
"""[steps] a hand that moved less than 1 cm over this many steps, the task not done, has stalled."""
DRIVE = 20
"""[steps] how long the stand-in drives once it has taken over (unless the task is done first)."""
DRIFT = 4
"""[steps] the hand moving against where the expert would move it, or the fingers left far from where it
would have them (its finger servo command over `FINGERS`), this many steps running is drift."""
FINGERS = 0.4
CORRECTION_SEEDS, PLAIN_SEEDS = 50_000, 60_000


class StandInCorrector:
    """A person's side of `TakeoverDevice`: watches the policy drive, takes over when it stalls, drifts (with
    `drift`: the hand has moved against where the expert would move it for `DRIFT` steps running) or runs
    out of the expert's time, drives as the expert would, lets go."""

    name = "standin"

    def __init__(self, env: gym.Env, patience: int, drift: bool, stall: int = STALL) -> None:
        self.expert = make_expert(env)
        self.patience, self.drift, self.stall = patience, drift, stall
        self.reset()

    def reset(self) -> None:
        self.expert.reset()
        self.tick, self.driving, self.takeovers, self.against = 0, 0, 0, 0
        self.grips: list[np.ndarray] = []
        self.wanted: np.ndarray | None = None

    def gripper_from(self, action: np.ndarray | None) -> None:
        pass

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        self.tick += 1
        grip = np.asarray(obs["observation"])[:3].copy()
        moved = grip - self.grips[-1] if self.grips else np.zeros(3)
        self.grips.append(grip)
        done = float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"])) < 0.05
        want = self.expert(obs)  # the expert follows the episode while the policy drives, as a person would
        if self.driving:
            self.driving = 0 if done else self.driving - 1
            return Command(want, touched=True)
        if self.wanted is not None and np.linalg.norm(self.wanted[:3]) > 0.5:
            against = float(moved @ self.wanted[:3]) < 0.3 * np.linalg.norm(moved) * np.linalg.norm(self.wanted[:3])
            self.against = self.against + 1 if against and np.linalg.norm(moved) > 0.005 else 0
        elif abs(float(want[3])) > FINGERS:  # the fingers not where the expert would have them, and staying so
            self.against += 1
        else:
            self.against = 0
        self.wanted = want
        stalled = len(self.grips) > self.stall and np.linalg.norm(grip - self.grips[-self.stall - 1]) < 0.01
        drifting = self.drift and self.against >= DRIFT
        late = self.tick > self.patience and self.tick % self.patience == 1
        if not done and (stalled or drifting or late):
            if not drifting:
                self.expert.reset()
                want = self.expert(obs)
            self.driving, self.grips, self.against = DRIVE - 1, [], 0
            self.takeovers += 1
            return Command(want, touched=True)
        return Command(np.zeros(4, np.float32))

    def close(self) -> None:
        pass


def timed(what: str, times: dict[str, float], run: Any) -> Any:
    start = time.perf_counter()
    out = run()
    times[what] = time.perf_counter() - start
    return out


def evaluate(run: pathlib.Path, episodes: int, report: pathlib.Path | None = None) -> dict[str, Any]:
    """`gym-fetch eval` of `run` on `episodes` unseen seeds; its report at `report` (default: in `run`)."""
    report = report or run / f"eval-{episodes}.json"
    if not report.exists():
        assert gym_fetch(["eval", str(run), "--episodes", str(episodes), "--json", str(report)]) == 0
    return json.loads(report.read_text())


def tight_starts(env_id: str, episodes: int) -> np.ndarray | None:
    """Which of the evaluation's seeds (1,000,000 on) start the object close beside something (`collect --starts
    tight`'s test); None where the task has none."""
    from fetch.generate.room import resets_tight
    from fetch.tasks.subtasks import Scene

    env = gym.make(env_id)
    scene = Scene(env.unwrapped.model)
    tight = np.array([resets_tight(env, seed, scene) for seed in range(EVAL_SEED_START, EVAL_SEED_START + episodes)])
    env.close()
    return tight if tight.any() else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Bin-pick-v2")
    parser.add_argument("--dir", required=True)
    parser.add_argument("--demos", type=int, default=100)
    parser.add_argument("--attempts", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=500, help="evaluation episodes (default 500)")
    parser.add_argument("--weight", type=int, default=None, help="--correction-weight (default: train's)")
    parser.add_argument("--steps", type=int, default=None, help="train --from's --steps (default: train's)")
    parser.add_argument("--drift", action="store_true", help="the stand-in also takes over on drift")
    parser.add_argument("--stall", type=int, default=STALL, help=f"the stand-in's STALL (default {STALL})")
    parser.add_argument("--style", default=None,
                        help="pad demos by this stand-in operator (fetch.testing.operators) instead of expert demos")
    parser.add_argument("--seed", type=int, default=100, help="--style: the pad demos' collection seed")
    parser.add_argument("--mission", default=None,
                        help="a benchmarks.mission folder: start from its policy (run) and generated demos; --style "
                             "names its stand-in, for the more pad demos")
    parser.add_argument("--starts", default="all", choices=("all", "tight"),
                        help="the corrected attempts' and the more demos' starts (collect --starts; default all)")
    parser.add_argument("--train-args", default="",
                        help='more flags for every `gym-fetch train`, e.g. "--precision fp32"')
    parser.add_argument("--expert-finger-noise", type=float, default=None,
                        help="collect's --expert-finger-noise for the expert demos (default: collect's, = the arm's)")
    args = parser.parse_args()
    if args.mission and not args.style:
        parser.error("--mission needs --style: the stand-in whose more pad demos the corrections are compared with")
    root = pathlib.Path(args.dir)
    root.mkdir(parents=True, exist_ok=True)
    times: dict[str, float] = {}
    env_id = args.env
    horizon = gym.spec(env_id).max_episode_steps or 50

    mission = pathlib.Path(args.mission) if args.mission else None
    base_run = mission / "run" if mission else root / "base"
    data = training_data(mission) if mission else [root / "demos"]
    seeing = fetch.learn.load(base_run).config if mission else None  # the cameras a mission's policy sees
    cameras = seeing.cameras if seeing else ()

    def collect_demos(out: pathlib.Path, episodes: int, seed: int, starts: str = "all") -> None:
        if args.style and not out.exists():
            teleop(env_id, out, episodes, args.style, seed, starts)
            for camera in cameras:  # what a camera policy learns from: its own cameras, size and quality
                assert seeing and gym_fetch(["render-obs", str(out), "--camera", camera, "--size",
                                             str(seeing.image_size), "--quality", seeing.image_quality]) == 0
        elif not out.exists():
            noise = args.expert_finger_noise
            fingers = [] if noise is None else ["--expert-finger-noise", str(noise)]
            assert gym_fetch(["collect", "--env", env_id, "--device", "expert", "--episodes", str(episodes),
                              "--render", "none", "--seed", str(seed), "--out", str(out), "--starts", starts,
                              *fingers]) == 0

    def train(out: pathlib.Path, *data: pathlib.Path, start: pathlib.Path | None = None) -> None:
        if not (out / "checkpoint.pt").exists() or not (out / "trained").exists():  # a stopped run resumes
            extra = ["--from", str(start)] if start else []
            extra += ["--correction-weight", str(args.weight)] if args.weight and start else []
            extra += ["--steps", str(args.steps)] if args.steps and start else []
            extra += shlex.split(args.train_args)
            assert gym_fetch(["train", *map(str, data), "--out", str(out), *extra]) == 0
            (out / "trained").touch()

    if not mission:
        timed("demos", times, lambda: collect_demos(root / "demos", args.demos, args.seed if args.style else 0))
        timed("train base", times, lambda: train(root / "base", root / "demos"))
    base_report = root / f"base-eval-{args.episodes}.json" if mission else None  # nothing written into the mission
    base = timed("eval base", times, lambda: evaluate(base_run, args.episodes, base_report))

    from_tight = "-tight" if args.starts == "tight" else ""
    corrected = root / ("corrected" + ("-drift" if args.drift else "") + (f"-stall{args.stall}" if args.stall != STALL
                                                                           else "") + from_tight)
    summary: dict[str, Any] = {}

    def correct() -> None:
        if corrected.exists():
            return
        env = gym.make(env_id, max_episode_steps=3 * horizon)
        person = StandInCorrector(env, patience=horizon, drift=args.drift, stall=args.stall)
        device = TakeoverDevice(PolicyDevice(env, base_run), person)
        images = dict(cameras=cameras, image_size=seeing.image_size,
                      image_quality=seeing.image_quality) if seeing and cameras else {}
        config = CollectConfig(env_id=env_id, out=str(corrected), episodes=args.attempts, max_steps=3 * horizon,
                               device="takeover", render="none", control_hz=0, keep_failures=True,
                               seed=CORRECTION_SEEDS, starts=args.starts, **images)
        result = Session(config, device, env=env, log=lambda _: None).run()
        summary.update(attempts=len(result.attempts), succeeded=sum(a.success for a in result.attempts))

    timed("collect corrections", times, correct)
    variant = "".join(f"-{k}{v}" for k, v in (("w", args.weight), ("s", args.steps)) if v)
    fixed_run = root / f"fixed{variant}{corrected.name[len('corrected'):]}"
    plain_run = root / f"plain{'-s' + str(args.steps) if args.steps else ''}{from_tight}"  # weight: corrections'
    more_demos = root / f"more{from_tight}"
    timed("train fixed", times, lambda: train(fixed_run, *data, corrected, start=base_run))
    fixed = timed("eval fixed", times, lambda: evaluate(fixed_run, args.episodes))
    timed("plain demos", times, lambda: collect_demos(more_demos, args.attempts, PLAIN_SEEDS, args.starts))
    timed("train plain", times, lambda: train(plain_run, *data, more_demos, start=base_run))
    plain = timed("eval plain", times, lambda: evaluate(plain_run, args.episodes))

    from fetch.dataset import open_dataset
    from fetch.dataset.reader import summarize

    with open_dataset(corrected) as ds:
        demos, takeovers, person, steps = summarize(ds).corrections
    print(machine_line("torch"))
    fingers = "" if args.expert_finger_noise is None else f" (--expert-finger-noise {args.expert_finger_noise})"
    kind = f"pad demos by the {args.style} stand-in (collection seed {args.seed})" if args.style else "expert demos"
    start = f"the policy of {mission} ({', '.join(map(str, data))})" if mission else f"{args.demos} {kind}{fingers}"
    where = " from tight starts" if from_tight else ""
    print(f"{env_id}, {start}, {args.attempts} attempts{where} with the stand-in ready to take over ({takeovers} "
          f"takeovers, {person} of their {steps} steps driven by it), {args.episodes} evaluation episodes\n")
    print(f"--correction-weight {args.weight or 'default'}, --steps {args.steps or 'default'} for --from\n")
    tight = tight_starts(env_id, args.episodes)
    columns = "" if tight is None else " tight starts: failed | other starts: failed |"
    print(f"| policy | success | 95 % interval |{columns}\n|---|---|---|{'---|---|' if columns else ''}")
    more = "pad" if args.style else "expert"
    first = "the mission's policy" if mission else f"{more} demos"
    for name, result in ((f"base ({first})", base), ("base + corrections (--from base)", fixed),
                         (f"base + {args.attempts} more {more} demos (--from base)", plain)):
        low, high = result["ci95"]
        failed = ~np.array(result["ever"])
        split = "" if tight is None else f" {(failed & tight).sum()} of {tight.sum()} | {(failed & ~tight).sum()} of " \
                                         f"{(~tight).sum()} |"
        print(f"| {name} | {100 * result['success_rate']:.1f} % | {100 * low:.1f}-{100 * high:.1f} % |{split}")
    round_time = sum(times.get(k, 0.0) for k in ("collect corrections", "train fixed", "eval fixed"))
    print("\n" + ", ".join(f"{k} {v:.0f} s" for k, v in times.items()) + f"; the correction round {round_time:.0f} s")


if __name__ == "__main__":
    main()
