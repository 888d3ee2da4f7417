"""`gym-fetch`: collect demonstrations, generate more, train and evaluate policies; inspect and convert datasets."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable, Sequence

from fetch._progress import StdoutError, guarded_stdout, stdout_gone

Command = Callable[[argparse.Namespace], int]


def _version() -> str:
    """`gym-fetch --version`: the package's, and the mujoco it runs on."""
    import mujoco

    import fetch

    return f"gym-fetch-v2 {fetch.__version__} (mujoco {mujoco.__version__}, python {sys.version.split()[0]})"


SUBCOMMANDS: tuple[str, ...] = (
    "fetch.commands.collect:add_parser",
    "fetch.commands.info:add_parser",
    "fetch.commands.replay:add_parser",
    "fetch.commands.render_obs:add_parser",
    "fetch.commands.merge:add_parser",
    "fetch.commands.split:add_parser",
    "fetch.commands.export:add_parser",
    "fetch.commands.gamepad:add_parser",
    "fetch.commands.train:add_parser",
    "fetch.commands.evaluate:add_parser",
    "fetch.commands.view:add_parser",
    "fetch.commands.generate:add_parser",
    "fetch.commands.subtasks:add_parser",
)
"""Every subcommand, in `gym-fetch --help`'s order: a function that adds its parser (`run` set to the function
that runs it), in the command layer (`fetch.commands`, one module per subcommand). What a command needs heavy
(torch, PyAV, minari, pygame) is imported only when it runs."""


def _parser() -> argparse.ArgumentParser:
    from fetch._references import resolve

    p = argparse.ArgumentParser(prog="gym-fetch", description=__doc__)
    p.add_argument("--version", action="version", version=_version())
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for reference in SUBCOMMANDS:
        resolve(reference)(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    # The parser is built inside: a Ctrl-C or SIGTERM while loading ends cleanly too.
    return run_stoppable(lambda: _parser().parse_args(argv))


def run_stoppable(parse: Callable[[], argparse.Namespace], prog: str | None = None) -> int:
    """Parse the arguments and run the command with the stop handlers held (`fetch.stopping`): the exit
    status, 128 + the signal after a stop."""
    from fetch.stopping import stop_on_signals

    try:
        with stop_on_signals():
            return _run(parse(), prog)
    except KeyboardInterrupt as e:  # while parsing, or landed while the handlers were put back
        return _stopped(e)
    except Exception as e:
        # A stop raised inside a C extension's call (h5py's attribute iteration, an import) comes out as
        # the extension's error, SystemError say, with the stop as its context: that is still the stop.
        stop = _stop_behind(e)
        if stop is None:
            raise
        return _stopped(stop)


def _stopped(e: KeyboardInterrupt) -> int:
    """The exit status after a stop signal: 128 + its number (Ctrl-C: 130, SIGTERM: 143)."""
    return 128 + int(getattr(e, "signum", signal.SIGINT))


def _run(args: argparse.Namespace, prog: str | None = None) -> int:
    from fetch.errors import FetchError

    try:
        with guarded_stdout():
            return int(args.run(args))
    except FetchError as e:
        print(f"{prog or 'gym-fetch ' + args.command}: error: {e}", file=sys.stderr)
        stop = _stop_behind(e)
        return 2 if stop is None else _stopped(stop)
    except KeyboardInterrupt as e:
        return _stopped(e)
    except OSError as e:  # what no tool turned into a FetchError: one line, not a traceback
        # A stop signal can break a pipe to a worker while the work is being wound down: that is
        # still the stop.
        stop = _stop_behind(e)
        if stop is not None:
            return _stopped(stop)
        if isinstance(e, BrokenPipeError):  # our stdout's reader went away (`| head`)
            stdout_gone()
            return 1
        name = prog or "gym-fetch " + args.command
        if isinstance(e, StdoutError):  # `> /dev/full`: the work is done, its report could not be written
            stdout_gone()
            print(f"{name}: error: cannot write to stdout ({e.strerror or e})", file=sys.stderr)
            return 1
        print(f"{name}: error: {e}", file=sys.stderr)
        return 2


def _stop_behind(e: BaseException) -> KeyboardInterrupt | None:
    """The stop signal (KeyboardInterrupt) that `e` was raised while handling, if any. (Python
    breaks any cycle when it sets `__context__`, so the chain ends.)"""
    context = e.__context__
    while context is not None and not isinstance(context, KeyboardInterrupt):
        context = context.__context__
    return context


if __name__ == "__main__":
    raise SystemExit(main())
