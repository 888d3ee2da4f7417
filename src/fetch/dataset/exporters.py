"""`gym-fetch export --to FORMAT`: one `Exporter` per format (`EXPORTERS`), and the subcommand that reads them.

An exporter says which of the subcommand's options it reads and which it needs; `run_export` refuses
any other before anything is read or written, with a line naming the formats that do read it, so
adding a format is one record here and its export function, not another branch.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable, Mapping

from fetch.dataset.export import export_lerobot, export_minari, export_npz, minari_root
from fetch.dataset.reader import FILE_HELP
from fetch.errors import FetchError, UnknownNameError


@dataclasses.dataclass(frozen=True)
class Exporter:
    name: str
    """`--to NAME`."""
    summary: str
    """what it writes, for `--help`."""
    reads: tuple[str, ...]
    """the options it reads besides the common ones (the file, `--demos`, `--force`), by their dest."""
    needs: Mapping[str, str]
    """the options it cannot do without, and what to give (for the error when one is missing)."""
    where: Callable[[], str]
    """where it writes, for the error that refuses an option it does not read."""
    run: Callable[[argparse.Namespace], str]
    """export as the parsed arguments say; the line to print."""


def _minari(args: argparse.Namespace) -> str:
    if args.dataset_id is not None and not args.dataset_id.strip():
        raise FetchError("--dataset-id is empty; give one such as fetch/reach/expert-v0, or leave it out for the "
                         "default")
    done = export_minari(args.file, args.dataset_id, demos=args.demos, force=args.force, author=args.author,
                         author_email=args.author_email, code_permalink=args.code_permalink,
                         description=args.description)
    dataset_id = done.path.relative_to(minari_root()).as_posix()
    return f"wrote {len(done.demos)} demo(s), {done.steps} steps, as Minari dataset {dataset_id} in {done.path}"


def _npz(args: argparse.Namespace) -> str:
    done = export_npz(args.file, args.out, demos=args.demos, force=args.force)
    return f"wrote {len(done.demos)} demo(s), {done.steps} steps, as npz files in {done.path}"


def _lerobot(args: argparse.Namespace) -> str:
    cameras = None if args.cameras is None else [c for c in args.cameras.split(",") if c and c != "none"]
    done = export_lerobot(args.file, args.repo_id, args.out, demos=args.demos, cameras=cameras,
                          image_size=args.image_size, fps=args.fps, force=args.force)
    return f"wrote {len(done.demos)} demo(s), {done.steps} frames, as LeRobotDataset {args.repo_id} in {done.path}"


EXPORTERS: tuple[Exporter, ...] = (
    Exporter("minari", "a local Minari dataset",
             reads=("dataset_id", "author", "author_email", "code_permalink", "description"), needs={},
             where=lambda: f"--to minari writes under $MINARI_DATASETS_PATH (now {minari_root()}), named by "
                           "--dataset-id",
             run=_minari),
    Exporter("npz", "the files `collect --format npz` writes", reads=("out",),
             needs={"out": "--out DIR, the directory for the files"},
             where=lambda: "--to npz writes into --out DIR", run=_npz),
    Exporter("lerobot", "a LeRobotDataset v3.0 (parquet + mp4)",
             reads=("repo_id", "out", "cameras", "image_size", "fps"),
             needs={"repo_id": "--repo-id NAME (namespace/name, e.g. me/fetch_drawer_open)"},
             where=lambda: "--to lerobot names the dataset with --repo-id", run=_lerobot),
)
_BY_NAME = {e.name: e for e in EXPORTERS}
OPTIONS = tuple(dict.fromkeys(dest for e in EXPORTERS for dest in e.reads))
"""Every format-specific option, by dest."""


def _flag(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def add_export_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """The `export` subcommand."""
    p = sub.add_parser("export", help="write a dataset as " + ", ".join(e.summary for e in EXPORTERS))
    p.add_argument("file", help=FILE_HELP)
    p.add_argument("--to", required=True, choices=tuple(_BY_NAME),
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
    p.set_defaults(run=run_export)


def run_export(args: argparse.Namespace) -> int:
    if args.to not in _BY_NAME:
        raise UnknownNameError("export format", args.to, tuple(_BY_NAME))
    exporter = _BY_NAME[args.to]
    for dest in OPTIONS:
        if getattr(args, dest, None) is not None and dest not in exporter.reads:
            readers = " or ".join(e.name for e in EXPORTERS if dest in e.reads)
            raise FetchError(f"{_flag(dest)} is for --to {readers}; {exporter.where()}")
    for dest, what in exporter.needs.items():
        if getattr(args, dest, None) is None:
            raise FetchError(f"--to {exporter.name} needs {what}")
    print(exporter.run(args))
    return 0
