"""`gym-fetch split`: remake a dataset's train/valid split (`fetch.dataset.edit.split`)."""

from __future__ import annotations

import argparse

from fetch.dataset.reader import FILE_HELP


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    s = sub.add_parser("split", help="remake mask/train and mask/valid from the successful demos")
    s.add_argument("file", help=FILE_HELP)
    s.add_argument("--valid", type=float, default=0.1, help="fraction of successful demos for validation (default 0.1)")
    s.add_argument("--seed", type=int, default=0, help="seed of the random assignment (default 0)")
    s.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.dataset.edit import split

    sizes = split(args.file, args.valid, args.seed)
    print(f"split {args.file}: " + ", ".join(f"{k} {v}" for k, v in sizes.items()))
    return 0
