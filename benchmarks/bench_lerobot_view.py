"""`gym-fetch export --to lerobot` and `gym-fetch view` on one dataset: wall time and CPU seconds (this
process and the render workers), which a shared machine's wall time overstates.

    python -m benchmarks.bench_lerobot_view DATASET [--out DIR] [--cameras front,wrist] [--size 128]
"""

from __future__ import annotations

import argparse
import pathlib
import resource
import shutil
import tempfile
import time

from fetch.dataset import open_dataset
from fetch.dataset.exports.export import export_lerobot
from fetch.dataset.page.view import build_view


def cpu() -> tuple[float, float]:
    me, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime, children.ru_utime + children.ru_stime


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset")
    p.add_argument("--out", default=None, help="where to write (default: a temporary directory, removed after)")
    p.add_argument("--cameras", default="front,wrist")
    p.add_argument("--size", type=int, default=128)
    args = p.parse_args()
    out = pathlib.Path(args.out or tempfile.mkdtemp(prefix="bench_lerobot_view_"))
    with open_dataset(args.dataset) as ds:
        steps = sum(int(ds.attrs(n)["num_samples"]) for n in ds.demo_names)
        states = steps + len(ds.demo_names)
        print(f"{ds.path}: {ds.env_id}, {len(ds.demo_names)} demos, {steps} steps")
    cameras = [c for c in args.cameras.split(",") if c]
    runs = [
        ("export --to lerobot", steps * len(cameras), lambda: export_lerobot(
            args.dataset, "bench/fetch", out / "lerobot", demos="all", cameras=cameras, image_size=args.size,
            force=True)),
        ("view", states, lambda: build_view(args.dataset, out / "view", size=args.size, force=True)),
    ]
    print("| command | frames rendered | wall [s] | CPU, this process [s] | CPU, render workers [s] | size on disk |")
    print("|---|---|---|---|---|---|")
    for name, frames, run in runs:
        start, (me0, kids0) = time.perf_counter(), cpu()
        run()
        wall, (me1, kids1) = time.perf_counter() - start, cpu()
        target = out / ("lerobot" if name.startswith("export") else "view")
        size = sum(f.stat().st_size for f in target.rglob("*") if f.is_file())
        print(f"| {name} | {frames} | {wall:.1f} | {me1 - me0:.1f} | {kids1 - kids0:.1f} | {size / 1e6:.2f} MB |")
    if args.out is None:
        shutil.rmtree(out)


if __name__ == "__main__":
    main()
