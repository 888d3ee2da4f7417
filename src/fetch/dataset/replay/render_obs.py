"""Add a camera's images to every demo of a dataset, from its saved states (`gym-fetch render-obs`).

Worker processes (one per core) each hold the env and an offscreen renderer, restore a demo's
states and render them; this process writes the images. Only the new arrays and the layout
attribute change; the files are edited as copies that replace the originals once every demo is rendered, so a
failed or interrupted run leaves the dataset as it was.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import time
from collections.abc import Iterator
from typing import Any

import h5py
import numpy as np

from fetch._durable import NO_ROOM, Rewrites, why
from fetch._progress import progress
from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.dataset import schema
from fetch.dataset.demo_file import storage
from fetch.dataset.holding import editing
from fetch.dataset.reader import open_dataset, resolve
from fetch.dataset.validation import require_valid
from fetch.errors import DatasetError, FetchError
from fetch.rendering import DEFAULT_IMAGE_QUALITY, check_image_quality, check_image_size
from fetch.stopping import raise_if_stopped


@dataclasses.dataclass(frozen=True)
class RenderReport:
    demos: int
    frames: int
    seconds: float
    workers: int

    @property
    def frames_per_second(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else 0.0


def default_workers() -> int:
    from fetch._processes import usable_cores

    return usable_cores()


# -- rendering ------------------------------------------------------------------------------------

def _store(group: h5py.Group, key: str, images: np.ndarray) -> None:
    for prefix, rows in (("obs", images[:-1]), ("next_obs", images[1:])):
        path = f"{prefix}/{key}"
        if path in group:
            del group[path]  # an earlier, interrupted run's (or --overwrite)
        group.create_dataset(path, data=rows, **storage(rows))


def _with_camera(layout: schema.Layout, camera: str, size: int, quality: str) -> schema.Layout:
    cameras = layout.cameras if camera in layout.cameras else (*layout.cameras, camera)
    return layout.with_cameras(cameras, size, quality)


def render_obs(path: str | os.PathLike[str], camera: str, size: int | None = None, workers: int | None = None,
               overwrite: bool = False, quality: str | None = None) -> RenderReport:
    """Add `obs/<camera>_image` and `next_obs/<camera>_image` (uint8, (T, size, size, 3)) to every demo, `size`
    [px] (None: that of the images the dataset holds, else `camera_obs.DEFAULT_IMAGE_SIZE`) drawn at `quality`
    (`rendering.IMAGE_QUALITIES`; None: the dataset's other images', else the default)."""
    if size is not None:
        check_image_size(size, "--size")
    if quality is not None:
        check_image_quality(quality, "--quality")
    workers = default_workers() if workers is None else workers
    if workers < 1:
        raise FetchError(f"--workers must be at least 1, got {workers}")
    index = resolve(path)
    with editing(index):
        with open_dataset(index) as ds:
            env_id, env_kwargs, layout = ds.env_id, ds.env_kwargs, ds.layout
            names = list(ds.demo_names)
            require_valid(ds, names, images=False)
            where = {name: ds.demo_file(name, write=True) for name in names}
        if size is None:  # the dataset's own size, bounded as --size is (its images match it: require_valid)
            size = layout.image_size if layout.cameras else DEFAULT_IMAGE_SIZE
            check_image_size(size, f"{index}'s image size")
        elif layout.cameras and size != layout.image_size:
            raise FetchError(f"{index} holds {layout.image_size}-pixel images ({', '.join(layout.cameras)}); a "
                             f"dataset has one image size, so use --size {layout.image_size}")
        others = [c for c in layout.cameras if c != camera]
        if quality is None:
            quality = layout.image_quality if layout.cameras else DEFAULT_IMAGE_QUALITY
        elif others and quality != layout.image_quality:
            raise FetchError(f"{index} holds {layout.image_quality}-quality images ({', '.join(others)}); a "
                             f"dataset has one image quality, so use --quality {layout.image_quality}")
        if camera in layout.cameras and not overwrite:
            raise FetchError(f"{index} already has {schema.image_key(camera)}; pass --overwrite to render it again")
        from fetch.dataset.render.frames import check_env_camera

        check_env_camera(env_id, env_kwargs, camera)  # before any work
        start = time.perf_counter()
        frames = 0
        key = schema.image_key(camera)
        new_layout = schema.layout_to_json(_with_camera(layout, camera, size, quality))
        workers = min(workers, max(1, len(names)))
        results = _rendered(index, env_id, env_kwargs, size, quality, camera, names, workers)
        try:
            with Rewrites() as rewrites:  # every file changes once all demos are rendered, or none does
                for name, images in progress(results, len(names), f"render {camera}"):
                    shard, group = where[name]
                    with rewrites.edit(shard) as f:
                        _store(f[group], key, images)
                    frames += len(images)
                with rewrites.edit(index) as f:  # last: the layout names the camera once every demo has it
                    f["data"].attrs["layout"] = new_layout
                raise_if_stopped()  # a stop whose exception Python swallowed: no file changes
        except OSError as e:
            if e.errno not in NO_ROOM:
                raise
            raise DatasetError(f"could not add {camera}'s images to {index}: {why(e)}; the dataset is "
                               "unchanged") from e
        return RenderReport(len(names), frames, time.perf_counter() - start, workers)


def _rendered(index: pathlib.Path, env_id: str, env_kwargs: dict[str, Any], size: int, quality: str, camera: str,
              names: list[str], workers: int) -> Iterator[tuple[str, np.ndarray]]:
    """(name, images) in the order of `names`, rendered by `workers` processes."""
    from fetch.dataset.render.render_ahead import render_ahead

    with open_dataset(index) as ds:
        jobs = ((name, ds.demo(name)["states"][()], schema.episode_seed(ds.attrs(name))) for name in names)
        for name, images in zip(names, render_ahead(env_id, env_kwargs, size, workers, jobs, (camera,),
                                                                   quality), strict=True):
            assert images is not None  # every demo has states
            yield name, images[camera]


def describe(report: RenderReport, camera: str, path: str) -> str:
    return (f"rendered {camera} for {report.demos} demo(s): {report.frames} frames in {report.seconds:.1f} s "
            f"({report.frames_per_second:.0f} frames/s, {report.workers} worker process(es)) into {path}")
