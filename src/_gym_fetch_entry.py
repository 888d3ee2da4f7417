"""The `gym-fetch` command's entry point, outside the `fetch` package so that it runs before the package
loads (MuJoCo, Gymnasium, NumPy: about a second). A Ctrl-C in that second ended the command with a
KeyboardInterrupt traceback, or "ImportError: initialization failed" when it landed inside a compiled
module's import; nothing has been written by then, so it now exits at once with 130,
as a stop does later. `fetch.cli.main` installs the real handlers (finish the saves, then stop). Once
it has returned, the work is done and the interpreter winds down (joins worker processes, runs exit
handlers): a stop signal then ends the process at once with 128 + its number, where before it could
raise where nothing catches it (a traceback from `view`'s exit)."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Sequence
from types import FrameType


def _quit(signum: int, frame: FrameType | None) -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    os._exit(128 + signum)


def main(argv: Sequence[str] | None = None) -> int:
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not when the caller ignores it
        signal.signal(signal.SIGINT, _quit)
    from fetch.cli import main as cli_main

    code = cli_main(argv)
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, _quit)
    return code
