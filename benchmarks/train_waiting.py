"""The pixel policy's training step beside other work: torch's threads, and how OpenMP's idle threads wait.

    python -m benchmarks.train_waiting [--rounds 3] [--steps 10] [--precision fp32|bf16|auto]
        [--conditions alone,one,two]

`gym-fetch train --inputs pixels` runs on every core (`--threads 0`). torch's CPU kernels share each
operation out to its OpenMP threads, and GNU OpenMP's idle thread spins a while for its next share before
it sleeps. On a laptop's two cores that also run something else, a spinning thread takes the core from
the thread whose share is late, and every operation waits for the last share. This times one training
step of the mission's shapes (`benchmarks.pixel_step`'s made-up batch: 64 examples, two cameras at
84 x 84) for each of `CONFIGS` (1 thread; 2 threads with OpenMP's default waiting, with
`OMP_WAIT_POLICY=PASSIVE`, or with a shorter spin), each alone, beside one busy core and beside two
(`--conditions`). The other work is MuJoCo stepping PickPlace's model in a loop, one process per busy
core, started before and stopped after each measurement. Each configuration is a process of its own
(OpenMP reads its variables when it starts); a figure is the median over `--rounds` rounds of `--steps`
steps after two untimed ones. Run from the repository root.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from benchmarks._machine import machine

CONFIGS: dict[str, tuple[int, dict[str, str]]] = {
    "1 thread": (1, {}),
    "2 threads, OpenMP's default waiting": (2, {}),
    "2 threads, OMP_WAIT_POLICY=PASSIVE": (2, {"OMP_WAIT_POLICY": "PASSIVE"}),
    "2 threads, GOMP_SPINCOUNT=10000": (2, {"GOMP_SPINCOUNT": "10000"}),
    "2 threads, GOMP_SPINCOUNT=30000": (2, {"GOMP_SPINCOUNT": "30000"}),
}
"""Each configuration: torch's threads and the OpenMP variables it starts with (GNU OpenMP spins
`GOMP_SPINCOUNT` times, 300000 by default, before a thread sleeps; PASSIVE: 0)."""
CONDITIONS = {"alone": 0, "one": 1, "two": 2}
"""Each condition: how many cores other work keeps busy."""
CONDITION_NAMES = {"alone": "alone", "one": "beside one busy core", "two": "beside two busy cores"}

BUSY = """
import gymnasium as gym
import mujoco

import fetch  # noqa: F401

env = gym.make("PickPlace-v2")
model, data = env.unwrapped.model, env.unwrapped.data
while True:
    mujoco.mj_step(model, data)
"""
"""The other work: one core's MuJoCo stepping, forever."""


def _child(args: argparse.Namespace) -> None:
    """One configuration's seconds a step, as JSON on stdout (OpenMP's setting came with the environment)."""
    from benchmarks.pixel_step import LAYOUTS, _batch, _config, _model, _steps
    from fetch.learn.train import hold_freed_memory

    hold_freed_memory()
    config, bf16 = _config(args)
    model, optimizer = _model(config, next(iter(LAYOUTS.values())))
    batch = _batch(config, args.batch_size)
    _steps(config, model, optimizer, batch, 2, bf16)
    print(json.dumps({"seconds": _steps(config, model, optimizer, batch, args.steps, bf16), "bf16": bf16}))


def _measure(args: argparse.Namespace, threads: int, openmp: dict[str, str], busy: int) -> dict[str, float]:
    env = {**{k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}, **openmp}
    others = [subprocess.Popen([sys.executable, "-c", BUSY], env={**env, "OMP_NUM_THREADS": "1"})
              for _ in range(busy)]
    try:
        time.sleep(2.0 if others else 0.0)  # the busy loops past their imports
        argv = [sys.executable, "-m", "benchmarks.train_waiting", "--child", "--threads", str(threads),
                "--steps", str(args.steps), "--precision", args.precision, "--batch-size", str(args.batch_size)]
        out = subprocess.run(argv, env=env, capture_output=True, text=True, check=True).stdout
    finally:
        for other in others:
            other.kill()
            other.wait()
    return dict(json.loads(out.splitlines()[-1]))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--steps", type=int, default=10, help="timed steps per measurement")
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--precision", choices=("auto", "fp32", "bf16"), default="auto")
    p.add_argument("--conditions", default="alone,one,two", help=f"of {', '.join(CONDITIONS)}")
    p.add_argument("--threads", type=int, default=0, help=argparse.SUPPRESS)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--image-size", type=int, default=84, help=argparse.SUPPRESS)
    p.add_argument("--cameras", default="front,wrist", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        _child(args)
        return
    conditions = [c for c in args.conditions.split(",") if c]
    unknown = sorted(set(conditions) - set(CONDITIONS))
    if unknown:
        raise SystemExit(f"--conditions: unknown {', '.join(unknown)}; choose of {', '.join(CONDITIONS)}")
    seconds: dict[tuple[str, str], list[float]] = {}
    bf16 = False
    for round_ in range(args.rounds):
        for condition in conditions:
            order = list(CONFIGS) if round_ % 2 == 0 else list(CONFIGS)[::-1]
            for name in order:
                threads, openmp = CONFIGS[name]
                figures = _measure(args, threads, openmp, CONDITIONS[condition])
                seconds.setdefault((condition, name), []).append(figures["seconds"])
                bf16 = bool(figures["bf16"])
    for key, value in machine("torch"):
        print(f"{key}: {value}")
    for variable in ("ATEN_CPU_CAPABILITY", "ONEDNN_MAX_CPU_ISA"):
        if variable in os.environ:
            print(f"{variable}: {os.environ[variable]}")
    print(f"\none cnn-chunk training step (batch {args.batch_size}, front and wrist at 84 px, "
          f"{'bf16' if bf16 else 'fp32'}); medians over {args.rounds} rounds of {args.steps} steps\n")
    print("| condition | threads and waiting | ms a step | steps/s | 6000 steps [min] | slower than the best by |")
    print("|---|---|---|---|---|---|")
    for condition in conditions:
        best = min(statistics.median(seconds[(condition, name)]) for name in CONFIGS)
        for name in CONFIGS:
            s = statistics.median(seconds[(condition, name)])
            print(f"| {CONDITION_NAMES[condition]} | {name} | {1000 * s:.0f} | {1 / s:.1f} | {6000 * s / 60:.1f} | "
                  f"{s / best:.2f}x |")


if __name__ == "__main__":
    main()
