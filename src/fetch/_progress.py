"""A small progress bar on stderr for long commands (only when stderr is a terminal)."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from typing import Any, TypeVar

T = TypeVar("T")


def progress(items: Iterable[T], total: int, label: str, unit: str = "demos") -> Iterator[T]:
    """Yield `items`, drawing `label [####    ] i/total unit, rate/s` as they pass."""
    stream = sys.stderr
    live = stream.isatty()
    start = last = time.perf_counter()
    done = 0
    for item in items:
        yield item
        done += 1
        now = time.perf_counter()
        if live and (now - last > 0.1 or done == total):
            last = now
            width = 24
            filled = int(width * done / total) if total else width
            rate = done / (now - start) if now > start else 0.0
            stream.write(f"\r{label} [{'#' * filled}{' ' * (width - filled)}] {done}/{total} {unit}, {rate:.1f}/s")
            stream.flush()
    if live and done:
        stream.write("\n")


@contextlib.contextmanager
def said_if_slow(text: str, after: float = 1.0) -> Iterator[None]:
    """Print `text` on stderr if the block is still running `after` seconds in: a long load says what it
    is doing, while a quick one (or one that fails at once, with its one-line error) prints nothing."""
    timer = threading.Timer(after, lambda: print(text, file=sys.stderr, flush=True))
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


def say(text: str) -> None:
    """Print a line on stdout for a person; once stdout fails (its reader went away: `| head`; a full
    disk: `> /dev/full`), go on without it. What is said is only news: the work, and saving it, must not
    stop because nobody reads it (the collector hung, its writer thread dead on the error)."""
    try:
        print(text, flush=True)
    except OSError:  # BrokenPipeError, ENOSPC
        stdout_gone()


def stdout_gone() -> None:
    """Point stdout at /dev/null: its reader went away, or it cannot be written; later lines (and the
    interpreter's flush at exit) then fail no more."""
    with contextlib.suppress(OSError):
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)


class StdoutError(OSError):
    """Stdout could not be written (`> /dev/full`, a failing terminal): the command's report, not its work."""


@contextlib.contextmanager
def _as_stdout_error() -> Iterator[None]:
    """An OSError inside, but a BrokenPipeError, raised again as a `StdoutError`."""
    try:
        yield
    except BrokenPipeError:
        raise
    except OSError as e:
        raise StdoutError(e.errno, e.strerror) from e


class _GuardedStdout:
    """Stdout, with its write errors told apart from every other OSError (`StdoutError`)."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        with _as_stdout_error():
            return int(self._stream.write(text))

    def flush(self) -> None:
        with _as_stdout_error():
            self._stream.flush()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


@contextlib.contextmanager
def guarded_stdout() -> Iterator[None]:
    """While inside, a failed write to stdout raises `StdoutError` (a BrokenPipeError stays one)."""
    before = sys.stdout
    sys.stdout = _GuardedStdout(before)  # type: ignore[assignment]
    try:
        yield
    finally:
        sys.stdout = before
