"""`gym-fetch replay`: its flags, and the replay they ask for (`fetch.dataset.replay.replaying.replay`, with a
`ReplayRequest`)."""

from __future__ import annotations

import argparse

from fetch.commands import flags
from fetch.dataset.reader import FILE_HELP


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    r = sub.add_parser("replay", help="re-simulate demos and compare them with what was recorded, or render "
                                      "them to video")
    r.add_argument("file", help=FILE_HELP)
    r.add_argument("--demo", default=None, help="a demo index or name, e.g. 3 or demo_3 (default: all)")
    r.add_argument("--check", action="store_true",
                   help="compare observations and states bit for bit (what replay does without --video)")
    r.add_argument("--verbose", action="store_true", help="a line per demo, exact or not")
    r.add_argument("--video", default=None, metavar="OUT",
                   help="render the saved states to OUT (.mp4 or .gif), one frame per state; with several demos "
                        "one file each, named OUT_demo_<i>")
    r.add_argument("--camera", default="front", help="the video's camera: front (default), side, behind or wrist")
    r.add_argument("--size", type=int, default=480, help="video width and height [px] (default 480)")
    r.add_argument("--fps", type=float, default=None, help="frames per second (default: the control rate, 25)")
    r.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.dataset.replay.replaying import ReplayRequest, replay

    return replay(flags.request_of(ReplayRequest, args))
