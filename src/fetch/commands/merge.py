"""`gym-fetch merge`: combine datasets of one env into one self-contained file (`fetch.dataset.edit.merge`)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    m = sub.add_parser("merge", help="combine datasets of the same env into one self-contained file")
    m.add_argument("inputs", nargs="+", metavar="FILE", help="datasets (files or collector directories), in order")
    m.add_argument("--out", required=True, help="the merged file (.hdf5)")
    m.add_argument("--force", action="store_true", help="replace --out if it exists")
    m.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.dataset.edit import merge

    report = merge(args.inputs, args.out, force=args.force)
    print(f"merged {len(args.inputs)} datasets: {report.demos} demos, {report.steps} steps -> {report.out} "
          "(" + ", ".join(f"{k} {v}" for k, v in sorted(report.masks.items())) + ")")
    return 0
