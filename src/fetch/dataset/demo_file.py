"""One demo as an HDF5 group, and as a file of its own (`episodes/demo_<i>.hdf5`)."""

from __future__ import annotations

import io
import pathlib
from collections.abc import Callable
from typing import Any

import h5py
import numpy as np

from fetch._durable import atomic_write
from fetch.dataset.episode import Demo


def hdf5_bytes(build: Callable[[h5py.File], None]) -> bytes:
    """An HDF5 file built in memory. Files reach the disk only through `atomic_write`: HDF5 itself
    does not survive a failed write (it crashed the process on a full disk in our tests)."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        build(f)
    return buffer.getvalue()


def write_demo_file(path: pathlib.Path, name: str, demo: Demo) -> None:
    """Write one demo as the group `/<name>` of a new HDF5 file, atomically."""
    atomic_write(path, hdf5_bytes(lambda f: write_demo_group(f.create_group(name), demo)))


def write_demo_group(group: h5py.Group, demo: Demo) -> None:
    for key, value in demo.attrs.items():
        group.attrs[key] = value
    for key, array in demo.arrays.items():
        group.create_dataset(key, data=array, **storage(array))


IMAGE_CHUNK = 8
"""[frames] the images of this many steps are compressed together (an HDF5 chunk)."""


def storage(array: np.ndarray) -> dict[str, Any]:
    """How `array` is stored: images (T, H, W, 3) uint8 gzip-compressed in chunks of `IMAGE_CHUNK` whole
    frames; the rest, small and read often, raw. h5py's own chunks for an image array were (21, 21, 21, 2)
    blocks, 1.9 kB each, so writing or reading a demo meant deflating or inflating hundreds: whole frames
    read 3.1x and write 2.2x as fast and take 17 % less room (the mission's Bin-place demos, 84 x 84, two
    cameras: 12 against 38 ms, 38 against 83 ms, 322 against 386 kB a demo; `benchmarks.image_storage`). A
    demo of no steps has nothing to chunk (HDF5 chunks, and so compresses, only arrays that have rows)."""
    if array.dtype != np.uint8 or array.ndim != 4 or not len(array):
        return {}
    return {"compression": "gzip", "compression_opts": 4, "chunks": (min(IMAGE_CHUNK, len(array)), *array.shape[1:])}


def read_demo_group(group: h5py.Group, keep: Callable[[str], bool] | None = None) -> Demo:
    """A saved demo, loaded (the inverse of `write_demo_group`); only the arrays whose path `keep` takes,
    where it is given."""
    arrays: dict[str, np.ndarray] = {}

    def visit(path: str, node: Any) -> None:
        if isinstance(node, h5py.Dataset) and (keep is None or keep(path)):
            arrays[path] = node[()]

    group.visititems(visit)
    return Demo(arrays, dict(group.attrs))
