"""Benchmark `collect --cameras`: does recording images keep the 25 Hz control rate?

    python -m benchmarks.bench_cameras [--env Drawer-open-v2] [--episodes 4] [--cameras front,wrist] [--size 128]

The expert collects at the real-time rate without a window, once without cameras and once with
them; the table gives how late each control tick started, the achieved rate and the time a tick
spends rendering. Both runs are in this one process, so they share the machine's load.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

from benchmarks._machine import machine_line
from fetch.teleop.expert import ExpertDevice
from fetch.teleop.session import CollectConfig, Session, make_env


def run(env_id: str, episodes: int, cameras: tuple[str, ...], size: int) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as out:
        config = CollectConfig(env_id=env_id, device="expert", render="none", out=out, episodes=episodes,
                               control_hz=25.0, cameras=cameras, image_size=size)
        env = make_env(config)
        session = Session(config, ExpertDevice(env), env=env, log=lambda _: None)
        start = time.perf_counter()
        summary = session.run()
        elapsed = time.perf_counter() - start
    ticks = np.array(session.ticks)
    late = (ticks[:, 1] - ticks[:, 0]) * 1e3
    work = np.diff(ticks[:, 0])  # deadline to deadline
    return {"ticks": len(ticks), "late_p50": float(np.percentile(late, 50)),
            "late_p99": float(np.percentile(late, 99)), "late_max": float(late.max()),
            "late_ticks": summary.late_ticks, "hz": 1.0 / float(np.median(work[work < 0.2])),
            "seconds": elapsed, "saved": summary.saved}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="Drawer-open-v2")
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--cameras", default="front,wrist")
    parser.add_argument("--size", type=int, default=128)
    args = parser.parse_args()
    cameras = tuple(c for c in args.cameras.split(",") if c)
    plain = run(args.env, args.episodes, (), args.size)
    images = run(args.env, args.episodes, cameras, args.size)
    print(f"\n{machine_line()}")
    print(f"{args.env}, 25 Hz, no window; MUJOCO_GL={os.environ.get('MUJOCO_GL')}")
    print(f"| {'measure':42} | {'no cameras':>12} | {(','.join(cameras) + f' {args.size}px'):>20} |")
    print(f"|{'-' * 44}|{'-' * 14}|{'-' * 22}|")
    rows = [("ticks", "ticks", "{:.0f}"), ("tick start after deadline p50 [ms]", "late_p50", "{:.2f}"),
            ("tick start after deadline p99 [ms]", "late_p99", "{:.2f}"),
            ("tick start after deadline max [ms]", "late_max", "{:.2f}"),
            ("ticks a whole period late", "late_ticks", "{:.0f}"), ("control rate [Hz]", "hz", "{:.2f}"),
            ("demos saved", "saved", "{:.0f}"), ("session, until every file is written [s]", "seconds", "{:.1f}")]
    for label, key, fmt in rows:
        print(f"| {label:42} | {fmt.format(plain[key]):>12} | {fmt.format(images[key]):>20} |")


if __name__ == "__main__":
    main()
