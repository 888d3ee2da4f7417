"""How a demo's camera images are stored in HDF5: the time to write and to read them back, and their size.

    python -m benchmarks.image_storage DATASET [--demos 60] [--rounds 3]

DATASET is any dataset with camera images (`collect --cameras`, `generate --cameras`, `render-obs`). The
`obs/<camera>_image` arrays of its first `--demos` demos are written into in-memory HDF5 files each way,
then read back whole (as `train --inputs pixels` loads them):

- now: `fetch.dataset.demo_file.storage`, gzip 4 in chunks of `IMAGE_CHUNK` whole frames;
- h5py's own chunks, gzip 4: how collect and generate stored images until 2026-11-27;
- one frame a chunk, gzip 4: how render-obs stored them until then.

Times are medians over `--rounds` rounds (each writes and reads every demo once), per demo with all its
cameras. Run from the repository root.
"""

from __future__ import annotations

import argparse
import io
import statistics
import time
from collections.abc import Callable
from typing import Any

import h5py
import numpy as np

from benchmarks._machine import machine
from fetch.dataset import open_dataset
from fetch.dataset.demo_file import storage

WAYS: dict[str, Callable[[np.ndarray], dict[str, Any]]] = {
    "now: chunks of IMAGE_CHUNK frames": storage,
    "h5py's own chunks (collect, generate before)": lambda a: {"compression": "gzip", "compression_opts": 4},
    "one frame a chunk (render-obs before)": lambda a: {"compression": "gzip", "compression_opts": 4,
                                                        "chunks": (1, *a.shape[1:])},
}


def _write(demo: list[np.ndarray], options: Callable[[np.ndarray], dict[str, Any]]) -> bytes:
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        for i, images in enumerate(demo):
            f.create_dataset(f"image_{i}", data=images, **options(images))
    return buffer.getvalue()


def _read(blob: bytes) -> int:
    with h5py.File(io.BytesIO(blob), "r") as f:
        return sum(int(f[key][()].shape[0]) for key in f)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    p.add_argument("dataset")
    p.add_argument("--demos", type=int, default=60)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    with open_dataset(args.dataset) as ds:
        cameras, size = ds.layout.cameras, ds.layout.image_size
        if not cameras:
            raise SystemExit(f"{args.dataset} holds no camera images; record some with --cameras or render-obs")
        demos = [[ds.demo(name)[f"obs/{camera}_image"][()] for camera in cameras]
                 for name in ds.demo_names[:args.demos]]
    steps = statistics.mean(len(d[0]) for d in demos)
    write: dict[str, list[float]] = {w: [] for w in WAYS}
    read: dict[str, list[float]] = {w: [] for w in WAYS}
    sizes: dict[str, float] = {}
    for _ in range(args.rounds):
        for way, options in WAYS.items():
            start = time.perf_counter()
            blobs = [_write(d, options) for d in demos]
            write[way].append((time.perf_counter() - start) / len(demos))
            start = time.perf_counter()
            for blob in blobs:
                _read(blob)
            read[way].append((time.perf_counter() - start) / len(demos))
            sizes[way] = statistics.mean(len(b) for b in blobs)
    for name, value in machine("h5py"):
        print(f"{name}: {value}")
    print(f"\n{len(demos)} demos of {args.dataset} ({steps:.0f} steps on average; {', '.join(cameras)} at {size} px), "
          f"obs images only; medians over {args.rounds} rounds\n")
    print("| stored as | write, ms a demo | read, ms a demo | kB a demo |\n|---|---|---|---|")
    for way in WAYS:
        print(f"| {way} | {1000 * statistics.median(write[way]):.1f} | {1000 * statistics.median(read[way]):.1f} | "
              f"{sizes[way] / 1000:.0f} |")


if __name__ == "__main__":
    main()
