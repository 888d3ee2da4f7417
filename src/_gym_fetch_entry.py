"""The `gym-fetch` command's entry point, outside the `fetch` package so that it runs before the package
loads (MuJoCo, Gymnasium, NumPy: about a second). A Ctrl-C in that second ended the command with a
KeyboardInterrupt traceback, or "ImportError: initialization failed" when it landed inside a compiled
module's import (22 of 30 tries); nothing has been written by then, so it now exits at once with 130,
as a stop does later. `fetch.cli.main` installs the real handlers (finish the saves, then stop)."""

from __future__ import annotations

import os
import signal
from collections.abc import Sequence
from types import FrameType


def _quit(signum: int, frame: FrameType | None) -> None:
    os._exit(128 + signum)


def main(argv: Sequence[str] | None = None) -> int:
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not when the caller ignores it
        signal.signal(signal.SIGINT, _quit)
    from fetch.cli import main as cli_main

    return cli_main(argv)
