"""`gym-fetch export`: its flags, one set for every format (`fetch.dataset.exports.exporters.EXPORTERS`), and the
export they ask for (`exporters.export`, with an `ExportRequest`)."""

from __future__ import annotations

import argparse

from fetch.commands import flags
from fetch.dataset.exports.exporters import EXPORTERS
from fetch.dataset.reader import FILE_HELP
from fetch.rendering import IMAGE_QUALITIES


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("export", help="write a dataset as " + ", ".join(e.summary for e in EXPORTERS))
    p.add_argument("file", help=FILE_HELP)
    p.add_argument("--to", required=True, choices=tuple(e.name for e in EXPORTERS),
                   help="; ".join(f"{e.name}: {e.summary}" for e in EXPORTERS))
    p.add_argument("--dataset-id", default=None, metavar="ID",
                   help="minari: (namespace/)name-v<version>, default fetch/<task>/<device>-v0 (with --demos other "
                        "than successful: fetch/<task>/<device>-<demos>-v0); it is written "
                        "under $MINARI_DATASETS_PATH (default ~/.minari/datasets)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="npz: the directory for the files; lerobot: the dataset's root (default "
                        "$HF_LEROBOT_HOME/<repo-id>, where LeRobotDataset(repo_id) looks)")
    p.add_argument("--repo-id", default=None, metavar="NAME", help="lerobot: the dataset's namespace/name")
    p.add_argument("--cameras", default=None, metavar="LIST",
                   help="lerobot: cameras to render as videos, comma-separated (default: the recorded ones, else "
                        "front,wrist; none: no video)")
    p.add_argument("--image-size", type=int, default=None, metavar="PX",
                   help="lerobot: video width and height (default: the recorded images', else 128)")
    p.add_argument("--image-quality", default=None, metavar="|".join(IMAGE_QUALITIES),
                   help="lerobot: how the videos are drawn (default full, as the viewer shows the scene and the "
                        "LeRobot env draws unless told; fast: as `generate --cameras` and a camera policy draw them "
                        "unless told, for a LeRobot policy to learn from the images such a policy learnt from)")
    p.add_argument("--fps", type=float, default=None, help="lerobot: frames per second (the control rate, 25)")
    p.add_argument("--demos", default="successful", metavar="WHICH",
                   help="successful (default), all, or a mask of the file (train, valid, failed)")
    p.add_argument("--force", action="store_true",
                   help="replace a Minari dataset of the same id, or the directory at --out (npz, LeRobot); each is "
                        "built beside and swapped in whole")
    g = p.add_argument_group("minari metadata")
    g.add_argument("--author", default=None, help="the dataset's author (default: none)")
    g.add_argument("--author-email", default=None, help="the author's e-mail address (default: none)")
    g.add_argument("--code-permalink", default=None,
                   help="a link to the code that made the data (default: none)")
    g.add_argument("--description", default=None, help="default: what the demos are and where they came from")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.dataset.exports.exporters import ExportRequest, export

    print(export(flags.request_of(ExportRequest, args)))
    return 0
