"""`gym-fetch subtasks`: where each of a dataset's demos begins each of its task's subtasks
(`fetch.generate.segments.describe_subtasks`)."""

from __future__ import annotations

import argparse

from fetch.dataset.reader import FILE_HELP

HELP = "cut a dataset's demos into their task's subtasks and print where each begins"


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    s = sub.add_parser("subtasks", help=HELP)
    s.add_argument("file", help=FILE_HELP)
    s.add_argument("--demo", default=None, help="a demo index or name (default: all)")
    s.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.generate.segments import describe_subtasks

    for line in describe_subtasks(args.file, args.demo):
        print(line)
    return 0
