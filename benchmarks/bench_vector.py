"""Steps per second of many worlds: one env, Gymnasium's Sync and Async vector envs, and FetchVectorEnv.

    python -m benchmarks.bench_vector                 # N = 1, 2, 8, 32, 128; a table at the end
    python -m benchmarks.bench_vector --quick         # N = 1, 2, 8, fewer rounds
    python -m benchmarks.bench_vector --out /tmp/bv.json --resume   # keep the Ns already measured

Every cell counts world-steps per second (N x vector steps / wall time) under uniform random actions,
with autoreset at the 50-step horizon (the single env is reset every 50 steps, as the others). For
each N all four are built once, then measured in short turns (`--seconds` each, `--rounds` times), so
that a change of load on a shared machine hits every column alike; the load average before and after is
printed. Rates are medians over the turns; a ratio is the median over the rounds of that round's rate
divided by the single env's rate in the same round (paired, so a loaded second hits both). The
CPU column is CPU time per world-step of this process (all its threads): how much work a step costs,
whatever the load; it leaves out AsyncVectorEnv's worker processes.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import statistics
import sys
import time
from typing import Any

import gymnasium as gym
import numpy as np

import fetch
from benchmarks._machine import machine_line
from fetch.vector import has_batch

KINDS = ("single", "sync", "async", "ours")


class Runner:
    """One backend at N worlds, stepped with pre-drawn random actions."""

    def __init__(self, kind: str, env_id: str, n: int, nthread: int) -> None:
        self.worlds = 1 if kind == "single" else n
        self.env: Any
        if kind == "single":
            self.env = gym.make(env_id)
        elif kind == "ours":
            self.env = fetch.make_vec(env_id, n, nthread=nthread)
        else:
            self.env = gym.make_vec(env_id, num_envs=n, vectorization_mode=kind)
        self.env.reset(seed=0)
        self.single = kind == "single"
        self.actions = np.random.default_rng(0).uniform(-1.0, 1.0, (64, self.worlds, 4)).astype(np.float32)
        self.count = 0
        for _ in range(3):  # first calls allocate
            self.step()

    def step(self) -> None:
        a = self.actions[self.count % 64]
        if self.single:
            _, _, terminated, truncated, _ = self.env.step(a[0])
            if terminated or truncated:
                self.env.reset()
        else:
            self.env.step(a)
        self.count += 1

    def measure(self, seconds: float) -> tuple[float, float]:
        """(world-steps per wall second, CPU µs of this process per world-step) over `seconds`."""
        steps, wall, cpu = 0, time.perf_counter(), time.process_time()
        while True:
            self.step()
            steps += 1
            elapsed = time.perf_counter() - wall
            if elapsed >= seconds:
                used = time.process_time() - cpu
                return self.worlds * steps / elapsed, 1e6 * used / (self.worlds * steps)

    def close(self) -> None:
        self.env.close()


def _load() -> str:
    path = pathlib.Path("/proc/loadavg")
    return " ".join(path.read_text().split()[:3]) if path.exists() else "?"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="PickPlace-v2", choices=fetch.ENV_IDS)
    parser.add_argument("--ns", default="1,2,8,32,128", help="numbers of worlds, comma-separated")
    parser.add_argument("--seconds", type=float, default=0.25, help="length of one turn [s]")
    parser.add_argument("--rounds", type=int, default=16, help="turns of each backend; medians are kept")
    parser.add_argument("--async-max", type=int, default=32,
                        help="largest N for AsyncVectorEnv (one process per world, ~110 MB each)")
    parser.add_argument("--nthread", type=int, default=0, help="FetchVectorEnv's C threads (0: every CPU)")
    parser.add_argument("--quick", action="store_true", help="N = 1, 2, 8; 6 rounds")
    parser.add_argument("--out", type=pathlib.Path, help="JSON file of measured Ns (written after each)")
    parser.add_argument("--resume", action="store_true", help="keep the Ns already in --out")
    args = parser.parse_args(argv)
    if args.quick:
        args.ns, args.rounds = "1,2,8", 6
    ns = [int(x) for x in args.ns.split(",")]
    cells: dict[str, dict[str, list[float]]] = {}
    if args.resume and args.out and args.out.exists():
        cells = json.loads(args.out.read_text())["cells"]

    load_before = _load()
    print(machine_line())
    print(f"{args.env}: FetchVectorEnv {'on C threads' if has_batch() else 'serial (no mujoco.batch)'}", flush=True)
    for n in ns:
        if str(n) in cells:
            continue
        kinds = [k for k in KINDS if k != "async" or n <= args.async_max]
        runners = {kind: Runner(kind, args.env, n, args.nthread) for kind in kinds}
        rates: dict[str, list[float]] = {kind: [] for kind in kinds}
        cpus: dict[str, list[float]] = {kind: [] for kind in kinds}
        for _ in range(args.rounds):
            for kind in kinds:
                rate, cpu = runners[kind].measure(args.seconds)
                rates[kind].append(rate)
                cpus[kind].append(cpu)
        for runner in runners.values():
            runner.close()
        cells[str(n)] = {**{f"{k}/rate": v for k, v in rates.items()}, **{f"{k}/cpu": v for k, v in cpus.items()}}
        med = {k: statistics.median(v) for k, v in rates.items()}
        print(f"  N={n:4d}: " + ", ".join(f"{k} {v:,.0f}" for k, v in med.items()) + f" (load {_load()})", flush=True)
        if args.out:
            args.out.write_text(json.dumps({"env": args.env, "cells": cells}, indent=1))
    load_after = _load()

    print(f"\n{args.env}, world-steps per second (median of {args.rounds} turns of {args.seconds} s; in brackets "
          f"the median ratio to the single env of the same round); load average {load_before} before, "
          f"{load_after} after\n")
    print("| N | single env | SyncVectorEnv | AsyncVectorEnv | FetchVectorEnv | CPU µs/world-step: single / ours |")
    print("|---|---|---|---|---|---|")
    for n in ns:
        cell = cells[str(n)]
        single = statistics.median(cell["single/rate"])

        def show(kind: str, cell: dict[str, list[float]] = cell) -> str:
            values = cell.get(f"{kind}/rate")
            if not values:
                return "-"
            ratio = statistics.median(v / s for v, s in zip(values, cell["single/rate"], strict=True))
            return f"{statistics.median(values):,.0f} ({ratio:.2f}x)"

        cpu = f"{statistics.median(cell['single/cpu']):.0f} / {statistics.median(cell['ours/cpu']):.0f}"
        print(f"| {n} | {single:,.0f} | {show('sync')} | {show('async')} | {show('ours')} | {cpu} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
