"""Benchmark a dataset's scale: is committing a demo as fast at 100,000 demos as at the first thousand?

    python -m benchmarks.bench_index_scale [--demos 100000] [--steps 5] [--dir /tmp/scale] [--every-demo 4000]

Real files, real fsyncs: a `DatasetWriter` (the collector's) commits `--demos` tiny Reach demos (the
same recorded demo under new names, so the disk and the index are what is measured, not physics)
and the rate is measured per window of 1,000 demos. Bar: the last window >= 90 % of the first.
`--every-demo N` also runs the old rule (the index rewritten for every demo) for N demos, for contrast.
Each run writes into a fresh directory under `--dir`, removed afterwards.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time

import gymnasium as gym
import h5py
import numpy as np

import fetch  # noqa: F401  (registers the ids)
from benchmarks._machine import machine_line
from fetch.dataset.episode import Demo, EpisodeBuffer
from fetch.dataset.formats import open_writer, recorded_layout
from fetch.dataset.writer import DatasetWriter

WINDOW = 1000


def one_demo(steps: int) -> tuple[gym.Env, Demo]:
    env = gym.make("Reach-v2")
    buf = EpisodeBuffer(recorded_layout(env), capacity=steps)
    obs, _ = env.reset(seed=0)
    buf.begin(obs, env.unwrapped.get_state())  # type: ignore[attr-defined]
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(np.float32([0.3, 0.0, 0.0, 1.0]))
        env.unwrapped.get_state(out=buf.state_row())  # type: ignore[attr-defined]
        buf.record(env.unwrapped.last_action, obs, float(reward), terminated, truncated, False, 0.0)  # type: ignore[attr-defined]
    attrs = {"seed": 0, "success": False, "env_id": "Reach-v2", "device": "bench", "attempt": 0,
             "control_hz": 0.0, "achieved_hz": 0.0, "started": 0.0, "ended": 0.0}
    return env, buf.demo(attrs)


def run(env: gym.Env, demo: Demo, count: int, root: str, every_demo: bool) -> list[float]:
    """[demos/s] per window of `WINDOW` commits (the last window may be shorter)."""
    out = tempfile.mkdtemp(prefix="scale-", dir=root)
    saved = {"n": 0}
    original = DatasetWriter._publish_due
    if every_demo:
        DatasetWriter._publish_due = lambda self, unpublished: True  # type: ignore[method-assign]
    try:
        writer = open_writer("hdf5", out, env, settings={"max_steps": 5}, device="bench",
                             on_saved=lambda name, d: saved.__setitem__("n", saved["n"] + 1))
        rates = []
        start = time.perf_counter()
        for i in range(count):
            writer.commit(demo)
            if (i + 1) % WINDOW == 0 or i + 1 == count:
                now = time.perf_counter()
                rates.append(((i % WINDOW) + 1) / (now - start))
                start = now
                print(f"  {i + 1:>7} demos: {rates[-1]:6.1f} demos/s, {saved['n']} published", flush=True)
        writer.close()
        with h5py.File(os.path.join(out, "demos.hdf5"), "r") as f:
            listed = len(f["data"])
            index_kb = os.path.getsize(os.path.join(out, "demos.hdf5")) / 1024
        assert listed == count, f"the index lists {listed} of {count} demos"
        print(f"  index: {listed} demos, {index_kb:.0f} KB", flush=True)
        return rates
    finally:
        DatasetWriter._publish_due = original  # type: ignore[method-assign]
        shutil.rmtree(out, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demos", type=int, default=100_000)
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--dir", default=tempfile.gettempdir())
    parser.add_argument("--every-demo", type=int, default=4000, help="demos with the old rule (0: skip)")
    args = parser.parse_args()
    env, demo = one_demo(args.steps)
    print(machine_line("h5py"))
    print(f"{args.steps}-step Reach demos into {args.dir}")
    rows = []
    if args.every_demo:
        print(f"the index rewritten for every demo, {args.every_demo} demos:")
        old = run(env, demo, args.every_demo, args.dir, every_demo=True)
        rows.append(("every demo (before)", args.every_demo, old[0], old[-1]))
    print(f"batched index (INDEX_BATCH), {args.demos} demos:")
    new = run(env, demo, args.demos, args.dir, every_demo=False)
    rows.append(("batched (now)", args.demos, new[0], new[-1]))
    print("\n| index rule | demos | first 1,000 [demos/s] | last 1,000 [demos/s] | last / first |")
    print("|---|---|---|---|---|")
    for rule, n, first, last in rows:
        print(f"| {rule} | {n:,} | {first:.0f} | {last:.0f} | {last / first:.2f} |")
    print(f"\nbar: last / first >= 0.90 for the batched rule: {'met' if new[-1] / new[0] >= 0.9 else 'NOT met'}")


if __name__ == "__main__":
    main()
