"""`python -m fetch.collect`: the same as `gym-fetch collect`."""

from __future__ import annotations

import sys
from collections.abc import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    from fetch.cli import main as cli_main

    return cli_main(["collect", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    raise SystemExit(main())
