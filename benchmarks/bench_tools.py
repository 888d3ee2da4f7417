"""Benchmark the dataset tools: render-obs frames/s by worker count, the LeRobot export, video, merge.

    python -m benchmarks.bench_tools [--env Drawer-open-v2] [--demos 12] [--size 84]

Makes a dataset with the scripted expert in a temporary directory, then times each tool on copies
of it. Speedups are ratios measured in this one run (the machines are shared and noisy).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import shutil
import tempfile
import time

import h5py

from benchmarks._machine import machine_line
from fetch.cli import main
from fetch.dataset.replay.render_obs import default_workers, render_obs


def timed(argv: list[str]) -> float:
    start = time.perf_counter()
    code = main(argv)
    if code != 0:
        raise SystemExit(f"{' '.join(argv)} failed with {code}")
    return time.perf_counter() - start


def run(env_id: str, demos: int, size: int) -> None:
    root = pathlib.Path(tempfile.mkdtemp(prefix="bench-tools-"))
    try:
        source = root / "source"
        timed(["collect", "--env", env_id, "--device", "expert", "--episodes", str(demos), "--render", "none",
               "--out", str(source)])
        with h5py.File(source / "demos.hdf5", "r") as f:
            steps = int(f["data"].attrs["total"])
        frames = steps + demos  # T + 1 states per demo
        rows = []
        cores = default_workers()
        seconds = {}
        for workers in sorted({1, cores}):
            copy = root / f"w{workers}"
            shutil.copytree(source, copy)
            report = render_obs(copy, "front", size, workers=workers)
            seconds[workers] = report.seconds
            rows.append((f"render-obs {size}px, {workers} worker(s)", f"{report.frames_per_second:.0f} frames/s",
                         f"{report.seconds:.2f} s for {report.frames} frames"))
        if cores > 1:
            rows.append((f"render-obs speedup, {cores} workers vs 1", f"{seconds[1] / seconds[cores]:.2f}x", ""))
        # The same LeRobot dataset twice: from a dataset without images (drawn from the states, `cores`
        # workers) and from the copy render-obs gave the front camera's images (read from the file).
        exported = {}
        for label, dataset in (("drawn", source), ("read", root / f"w{cores}")):
            exported[label] = timed(["export", str(dataset), "--to", "lerobot", "--repo-id", "bench/tools",
                                     "--out", str(root / f"lerobot-{label}"), "--cameras", "front",
                                     "--image-size", str(size), "--image-quality", "fast"])
            rows.append((f"export --to lerobot, front {size}px, images {label}",
                         f"{steps / exported[label]:.0f} frames/s", f"{exported[label]:.2f} s for {steps} frames"))
        rows.append(("export, images read vs drawn", f"{exported['drawn'] / exported['read']:.2f}x", ""))
        video = root / "demo.mp4"
        t = timed(["replay", str(source), "--demo", "0", "--video", str(video), "--size", "480"])
        with h5py.File(source / "demos.hdf5", "r") as f:
            n = int(f["data/demo_0"].attrs["num_samples"]) + 1
        rows.append(("replay --video 480px mp4 (render + encode)", f"{n / t:.0f} frames/s", f"{t:.2f} s, {n} frames"))
        gif = root / "demo.gif"
        t = timed(["replay", str(source), "--demo", "0", "--video", str(gif), "--size", "240"])
        rows.append(("replay --video 240px gif", f"{n / t:.0f} frames/s", f"{t:.2f} s"))
        other = root / "other"
        timed(["collect", "--env", env_id, "--device", "expert", "--episodes", str(demos), "--render", "none",
               "--seed", "1000", "--out", str(other)])
        t = timed(["merge", str(source), str(other), "--out", str(root / "merged.hdf5")])
        rows.append((f"merge 2 x {demos} demos", f"{2 * demos / t:.0f} demos/s", f"{t:.2f} s"))
        t = timed(["split", str(root / "merged.hdf5"), "--valid", "0.1"])
        rows.append((f"split {2 * demos} demos", f"{t * 1e3:.0f} ms", ""))
    finally:
        shutil.rmtree(root, ignore_errors=True)
    print(f"\n{machine_line('h5py')}")
    print(f"{env_id}: {demos} demos, {steps} steps, {frames} states; MUJOCO_GL={os.environ.get('MUJOCO_GL')}")
    print(f"| {'measure':46} | {'result':>14} | {'detail':30} |")
    print(f"|{'-' * 48}|{'-' * 16}|{'-' * 32}|")
    for label, result, detail in rows:
        print(f"| {label:46} | {result:>14} | {detail:30} |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="Drawer-open-v2")
    parser.add_argument("--demos", type=int, default=12)
    parser.add_argument("--size", type=int, default=84)
    args = parser.parse_args()
    run(args.env, args.demos, args.size)
