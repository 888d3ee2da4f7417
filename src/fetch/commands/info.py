"""`gym-fetch info`: summarise and validate a recording, whatever its format
(`fetch.dataset.replay.recordings.inspect_recording`)."""

from __future__ import annotations

import argparse

from fetch.dataset.reader import FILE_HELP


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    i = sub.add_parser("info", help="summarise and validate a dataset; non-zero exit if it is inconsistent")
    i.add_argument("file", help=FILE_HELP)
    i.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.dataset.replay.recordings import inspect_recording

    info = inspect_recording(args.file)
    print("\n".join(info.summary))
    if info.problems:  # the first 50
        print(f"INVALID: {len(info.problems)} problem(s):")
        for p in info.problems[:50]:
            print(f"  - {p}")
        return 1
    print("valid")
    return 0
