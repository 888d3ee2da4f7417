"""`gym-fetch render-obs`: add a camera's images to every demo of a dataset
(`fetch.dataset.replay.render_obs.render_obs`)."""

from __future__ import annotations

import argparse

from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.dataset.reader import FILE_HELP
from fetch.rendering import IMAGE_QUALITIES, QUALITY_HELP


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    o = sub.add_parser("render-obs", help="add a camera's images to every demo, rendered from the saved states")
    o.add_argument("file", help=FILE_HELP)
    o.add_argument("--camera", required=True, help="a camera of the env, e.g. front or wrist")
    o.add_argument("--size", type=int, default=None,
                   help=f"image width and height [px] (default: the dataset's images', else {DEFAULT_IMAGE_SIZE})")
    o.add_argument("--quality", default=None, choices=IMAGE_QUALITIES,
                   help=QUALITY_HELP.replace("the default", "the default for a dataset without images; one with "
                                             "images keeps theirs"))
    o.add_argument("--workers", type=int, default=None, help="render processes (default: one per core)")
    o.add_argument("--overwrite", action="store_true", help="render a camera the dataset already has again")
    o.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.dataset.replay.render_obs import describe, render_obs

    report = render_obs(args.file, args.camera, args.size, workers=args.workers, overwrite=args.overwrite,
                        quality=args.quality)
    print(describe(report, args.camera, args.file))
    return 0
