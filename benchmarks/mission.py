"""The measure of the whole tool: ten demonstrations with a pad, then a policy that solves the task.

    .venv-train/bin/python -m benchmarks.mission [--env PickPlace-v2] [--style standin] [--demos 10]
        [--generated 1000] [--generate-noise STD] [--workers 2] [--dir /tmp/mission]
        [--inputs pixels [--image-size 64] [--image-quality fast]] [--generate-args "--retries 0"]
        [--train-args "--steps 3000"]

1. teleop: 10 demos through the real gamepad path (SDL's virtual pad, the real `GamepadDevice` and
   collector), driven by a stand-in for a person of `--style` (`fetch.testing.operators`: the expert's
   intent, carried out with that style's habits: pace, pauses, a missed grasp, gripper habits,
   approach paths; docs/operators.md);
2. `gym-fetch generate` multiplies them into `--generated` demos (with `--inputs pixels`, rendering the
   front and wrist cameras' images of each in its workers, at `--image-quality`): a `--tight` share of them
   (default 0.2) from the starts where the object stands close beside something (`generate --starts tight`,
   a second dataset, `generated-tight`), where the task has such starts, the rest from every start;
3. `gym-fetch train` with its defaults on both (with `--inputs pixels`, the pixel policy: `train --inputs pixels`);
4. `gym-fetch eval --episodes 100` on seeds disjoint from the data's.
Each stage is skipped when its output exists (run again after an interruption). Prints the time of
each stage and the success with its 95 % interval. Bar: >= 90 % within 30 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import time

from benchmarks._machine import machine_line
from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.rendering import DEFAULT_IMAGE_QUALITY, IMAGE_QUALITIES


def teleop(env_id: str, out: pathlib.Path, demos: int, style: str, seed: int = 0,
           starts: str = "all") -> tuple[float, float]:
    """([s] wall time, [s] what a person at 25 Hz would have spent steering), the demos made from `starts`
    (`collect --starts`)."""
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    from fetch.testing import operators, vpad
    from fetch.timing import CONTROL_DT

    vpad.init_headless()
    pad = vpad.VirtualPad()
    start = time.perf_counter()
    try:
        summary = operators.drive(pad, env_id, style, out, demos, seed, starts)
    finally:
        pad.detach()  # unplugged, so a later session in this process finds one pad only
    steps = sum(a.steps for a in summary.attempts)
    print(f"  teleop: {summary.describe()}")
    return time.perf_counter() - start, steps * CONTROL_DT


def demo_length(path: pathlib.Path) -> float:
    """[steps] the mean length of a dataset's demos."""
    from fetch.dataset import open_dataset

    with open_dataset(path) as ds:
        return sum(int(ds.attrs(n)["num_samples"]) for n in ds.demo_names) / max(1, len(ds.demo_names))


def mission_dir(base: str | pathlib.Path, env_id: str, style: str, inputs: str = "state",
                image_size: int = DEFAULT_IMAGE_SIZE, image_quality: str = DEFAULT_IMAGE_QUALITY) -> pathlib.Path:
    """Where a mission keeps its stages under `--dir` `base`: one folder per task and style, and per image size and
    quality for the camera path (its pad demos are the same as the state path's for the same seed)."""
    root = pathlib.Path(base) / env_id
    return root / (f"{style}-pixels{image_size}-{image_quality}" if inputs == "pixels" else style)


def training_data(stages: pathlib.Path) -> list[pathlib.Path]:
    """The datasets a mission's `train` learns from, in the folder `stages` (`mission_dir`): its generated demos,
    and those from tight starts where the task has them."""
    return [d for d in (stages / "generated", stages / "generated-tight") if d.exists()]


TIGHT_SEED = 500_000
"""`generate --seed` of the tight starts' dataset: its attempts the same seed and number would be the other's
(the same demo twice); below the evaluation's seeds (1,000,000 on)."""


def gym_fetch(*args: str) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "fetch.cli", *args], check=True)
    return time.perf_counter() - start


def live_rate(run: pathlib.Path, steps: int = 200) -> float:
    """[Hz] how fast the policy of `run` acts in one env, rendering its cameras as it goes (a pixel policy's
    images; nothing for a state policy): what `collect --device policy` needs beside its window."""
    import gymnasium as gym
    import torch

    import fetch.learn

    torch.set_num_threads(1)  # as the collector's policy device runs it
    policy = fetch.learn.load(run)
    env = gym.make(policy.env_id, **policy.env_kwargs, **policy.observation_kwargs)
    obs, _ = env.reset(seed=10**7)
    policy.reset()
    start = time.perf_counter()
    for _ in range(steps):
        obs, *_ = env.step(policy(obs))
    env.close()
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="PickPlace-v2")
    parser.add_argument("--demos", type=int, default=10)
    parser.add_argument("--generated", type=int, default=1000)
    parser.add_argument("--tight", type=float, default=0.2,
                        help="the share of --generated made from tight starts (generate --starts tight), where the "
                             "task has any (default %(default)s; 0: none)")
    parser.add_argument("--style", default="standin",
                        help="the stand-in operator's way of driving (fetch.testing.operators STYLES; default standin)")
    parser.add_argument("--seed", type=int, default=0, help="the collection's first reset seed and the operator's")
    parser.add_argument("--generate-noise", type=float, default=None,
                        help="gym-fetch generate --noise (default: generate's own default)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--dir", default="/tmp/mission")
    parser.add_argument("--inputs", default="state", choices=("state", "pixels"),
                        help="what the policy sees (gym-fetch train --inputs; default state)")
    parser.add_argument("--image-size", type=int, default=DEFAULT_IMAGE_SIZE,
                        help=f"--inputs pixels: the images' side [px] (default {DEFAULT_IMAGE_SIZE}, generate's)")
    parser.add_argument("--image-quality", default=DEFAULT_IMAGE_QUALITY, choices=IMAGE_QUALITIES,
                        help="--inputs pixels: how the images are drawn (default %(default)s, generate's)")
    parser.add_argument("--generate-args", default="",
                        help="more `gym-fetch generate` flags, e.g. \"--no-fit-opening\" (use another --dir)")
    parser.add_argument("--train-args", default="", help="more `gym-fetch train` flags, e.g. \"--steps 3000\"")
    args = parser.parse_args()
    root = mission_dir(args.dir, args.env, args.style, args.inputs, args.image_size, args.image_quality)
    cameras: list[str] = []
    if args.inputs == "pixels":
        cameras = ["--cameras", "front,wrist", "--image-size", str(args.image_size), "--image-quality",
                   args.image_quality]
    root.mkdir(parents=True, exist_ok=True)
    timing_file = root / "timing.json"
    timing = json.loads(timing_file.read_text()) if timing_file.exists() else {}
    human, generated, run, result = root / "human", root / "generated", root / "run", root / "eval.json"
    tight = root / "generated-tight"
    print(machine_line("torch"))
    seeing = f"pixels, {args.image_size} px {args.image_quality}" if args.inputs == "pixels" else "state"
    print(f"{args.env}, {args.demos} pad demos -> {args.generated} generated -> train ({seeing}) -> eval "
          f"{args.episodes}")
    if "teleop" not in timing:
        timing["teleop"], timing["person"] = teleop(args.env, human, args.demos, args.style, args.seed)
        timing_file.write_text(json.dumps(timing))
    if "generate" not in timing:
        noise = [] if args.generate_noise is None else ["--noise", str(args.generate_noise)]
        common = ["--source", str(human), "--workers", str(args.workers), *noise, *cameras, *args.generate_args.split()]
        n_tight = round(args.tight * args.generated)
        started = time.perf_counter()
        if n_tight:  # a task without tight starts says so and makes none (resumes like any generate)
            tight_argv = ["generate", "--starts", "tight", "--seed", str(TIGHT_SEED), "--out", str(tight), "--demos",
                          str(n_tight), *common]
            made = subprocess.run([sys.executable, "-m", "fetch.cli", *tight_argv]).returncode == 0
            if not made and any((tight / "episodes").glob("*")):
                raise SystemExit(f"generate --starts tight into {tight} failed")
            if not made:
                shutil.rmtree(tight, ignore_errors=True)
                print(f"{args.env}: no tight starts; all {args.generated} demos from every start", flush=True)
        gym_fetch("generate", "--out", str(generated), "--demos",
                  str(args.generated - (n_tight if tight.exists() else 0)), *common)
        timing["generate"] = time.perf_counter() - started
        timing_file.write_text(json.dumps(timing))
    if "train" not in timing:
        inputs = ["--inputs", "pixels"] if args.inputs == "pixels" else []
        data = map(str, training_data(root))
        timing["train"] = gym_fetch("train", *data, "--out", str(run), *inputs, *args.train_args.split())
        timing_file.write_text(json.dumps(timing))
    if "eval" not in timing:
        timing["eval"] = gym_fetch("eval", str(run), "--episodes", str(args.episodes), "--json", str(result))
        timing_file.write_text(json.dumps(timing))
    if "live_hz" not in timing:
        timing["live_hz"] = live_rate(run)
        timing_file.write_text(json.dumps(timing))
    outcome = json.loads(result.read_text())
    compute = timing["generate"] + timing["train"] + timing["eval"]
    print("\n| stage | wall time |")
    print("|---|---|")
    print(f"| {args.demos} pad demos (a person at 25 Hz: {timing['person']:.0f} s of steering) | "
          f"{timing['teleop']:.0f} s |")
    for stage in ("generate", "train", "eval"):
        print(f"| {stage} | {timing[stage]:.0f} s |")
    print(f"| generate + train + eval | {compute / 60:.1f} min |")
    print(f"\nacting live in one env, cameras rendered: {timing['live_hz']:.0f} Hz")
    lo, hi = outcome["ci95"]
    horizon = outcome.get("horizon", 50)
    registered = outcome.get("registered_horizon", horizon)
    at_registered = (f", at the registered {registered} steps {100 * outcome['registered_success_rate']:.0f} %"
                     if registered != horizon else "")
    print(f"\n{args.style} on {args.env}, {args.inputs}: success {100 * outcome['success_rate']:.0f} % (95 % interval "
          f"{100 * lo:.0f}-{100 * hi:.0f} %) over {outcome['episodes']} episodes at the policy's horizon of {horizon} "
          f"steps{at_registered}; mean length {outcome['mean_length']:.1f} (the pad demos: "
          f"{demo_length(human):.1f}); "
          f"bar (>= 90 % within 30 min): {'met' if outcome['success_rate'] >= 0.9 and compute <= 1800 else 'NOT met'}")


if __name__ == "__main__":
    main()
