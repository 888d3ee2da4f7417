"""`gym-fetch view`: a static web page of a dataset (`fetch.dataset.page.view.build_view`)."""

from __future__ import annotations

import argparse

from fetch.dataset.reader import FILE_HELP


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("view", help="write a static web page of a dataset: a looping video per demo, plots of "
                                    "actions and observations, histograms of length and success")
    p.add_argument("file", help=FILE_HELP)
    p.add_argument("--out", required=True, metavar="DIR", help="the page's directory (index.html, videos/, data/)")
    p.add_argument("--camera", default="front", help="the videos' camera: front (default), side, behind or wrist")
    p.add_argument("--size", type=int, default=128, help="video width and height [px] (default 128)")
    p.add_argument("--workers", type=int, default=None, help="render processes (default: one per core)")
    p.add_argument("--force", action="store_true", help="replace --out if it is not empty")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.dataset.page.view import build_view, describe

    report = build_view(args.file, args.out, camera=args.camera, size=args.size, workers=args.workers,
                        force=args.force)
    print(describe(report))
    return 0
