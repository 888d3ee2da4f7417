"""Progress on stderr for long commands: a bar redrawn on a terminal, a line every few seconds elsewhere."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from typing import Any, TypeVar

T = TypeVar("T")


EVERY_LINE = 5.0
"""[s] How often a long command writes a progress line where stderr is not a terminal (a file or a pipe: CI,
`nohup`, a notebook): a sign of life in the log without flooding it."""
REDRAW = 0.1
"""[s] How often the bar is redrawn on a terminal, at most."""


class Bar:
    """One progress line on stderr, `show(text)` as the work goes: on a terminal redrawn in place; elsewhere
    written as a line of its own every `EVERY_LINE` seconds, so a work that ends sooner prints nothing, and one
    that printed ends with its last line (`show(text, last=True)`)."""

    def __init__(self) -> None:
        self.live = sys.stderr.isatty()
        self.last = time.perf_counter()
        self.drawn = False
        """something is on the terminal's line, or lines were written"""

    def show(self, text: str, last: bool = False) -> None:
        now = time.perf_counter()
        if self.live:
            if last or now - self.last >= REDRAW:
                self.last, self.drawn = now, True
                sys.stderr.write(f"\r{text}")
                sys.stderr.flush()
        elif now - self.last >= EVERY_LINE or (last and self.drawn):
            self.last, self.drawn = now, True
            sys.stderr.write(f"{text}\n")
            sys.stderr.flush()

    def end(self) -> None:
        """Finish the terminal's line (what follows starts on a line of its own); again does nothing."""
        if self.live and self.drawn:
            sys.stderr.write("\n")
            sys.stderr.flush()
        self.drawn = False


def bar_text(label: str, done: int, total: int, rest: str) -> str:
    """`label [####    ] done/total rest`."""
    width = 24
    filled = min(width, int(width * done / total)) if total else width
    return f"{label} [{'#' * filled}{' ' * (width - filled)}] {done}/{total} {rest}"


def progress(items: Iterable[T], total: int, label: str, unit: str = "demos") -> Iterator[T]:
    """Yield `items`, showing `label [####    ] i/total unit, rate/s` as they pass (`Bar`)."""
    bar = Bar()
    start = time.perf_counter()
    done = 0
    try:
        for item in items:
            yield item
            done += 1
            elapsed = time.perf_counter() - start
            rate = done / elapsed if elapsed > 0 else 0.0
            bar.show(bar_text(label, done, total, f"{unit}, {rate:.1f}/s"), last=done == total)
    finally:  # an error's message, too, starts on a line of its own
        bar.end()


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
