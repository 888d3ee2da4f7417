"""How a tool stops on a signal: SIGTERM as Ctrl-C, and the saves finished whatever comes next (the bottom
layer: the collector, the editing tools, the exports and generate all stop through it)."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any

from fetch._environ import environ

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Stopped(KeyboardInterrupt):
    """A stop signal arrived (Ctrl-C's SIGINT, or SIGTERM from `kill`, a service manager, a scheduler)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class _State:
    depth = 0
    polled = False
    """a control loop asks `raise_if_stopped` every tick, so the handler only records the stop."""
    requested: int | None = None
    """the stop signal received and not yet acted on."""
    handled = False
    """the stop is being acted on (the saves are being finished)."""
    hook: Any = sys.unraisablehook
    """the unraisable-exception hook to restore, and to pass what is not a stop to."""
    deferring = False
    """a dropped stop's re-delivery is being set up (`_dropped`): a stop now is deferred to it."""
    deferred = False
    """a stop came while `deferring`."""
    timers: list[threading.Timer] = []
    """the re-deliveries of dropped stops not yet made (`_dropped`), cancelled when the tool leaves
    `stop_on_signals`."""


_STATE = _State()


REDELIVER = 0.02
"""[s] after which a stop whose exception Python dropped is delivered again."""


def _stop(signum: int, frame: FrameType | None) -> None:
    if _STATE.deferring:  # inside `_dropped`, where an exception would be dropped again
        _STATE.requested, _STATE.deferred = signum, True
        return
    if _STATE.handled:
        os.write(2, b"still finishing the saves; they will complete, then the session stops\n")
        return
    _STATE.requested = signum
    if not _STATE.polled or not _STATE.depth:  # outside `stop_on_signals` nothing asks for it later
        raise Stopped(signum)


def _dropped(unraisable: Any) -> None:
    """`sys.unraisablehook` while stopping on signals: a `Stopped` raised in a weakref callback or a
    `__del__` is dropped by Python (printed as "Exception ignored in ..."), and the tool would carry on
    as if no Ctrl-C had come. The signal is delivered again
    once out of it; anything else goes to the hook before."""
    if isinstance(unraisable.exc_value, Stopped) and not _STATE.handled:
        # On a loaded machine the timer's thread can take longer than REDELIVER to start, and its signal
        # then arrives while this hook still runs: it is deferred to the next timer, not raised here.
        signum = unraisable.exc_value.signum
        _STATE.deferred = True
        while _STATE.deferred:
            _STATE.deferring, _STATE.deferred = True, False
            try:
                timer = threading.Timer(REDELIVER, _redeliver, (signum,))
                timer.daemon = True
                _STATE.timers.append(timer)
                timer.start()
            finally:
                _STATE.deferring = False
        return
    _STATE.hook(unraisable)


def _redeliver(signum: int) -> None:
    """A timer's: the dropped stop again, unless the tool has left `stop_on_signals` meanwhile (it acted on
    the stop another way, `raise_if_stopped` or an earlier re-delivery). Sent then, it landed in the exit's
    own code, an atexit callback, printed as "Exception ignored" (a flaky tests/test_tools.py)."""
    if _STATE.depth:
        os.kill(os.getpid(), signum)


def raise_if_stopped() -> None:
    """Raise `Stopped` if a stop signal arrived inside `stop_on_signals` and was not acted on: the
    exception its handler raised can be lost (Python ignores exceptions raised in a weakref callback or
    `__del__`), so the control loop asks once per tick. Outside, a stop an earlier command received
    (in the same process: the Python API after `fetch.cli.main`) is not this caller's."""
    if _STATE.requested is not None and not _STATE.handled and _STATE.depth:
        raise Stopped(_STATE.requested)


@contextlib.contextmanager
def polled() -> Iterator[None]:
    """While inside, a stop signal is only recorded and the caller's loop raises it (`raise_if_stopped`)
    at its next tick: raised from the handler, it could land in a weakref callback or `__del__`, where
    Python prints it as an ignored exception."""
    before = _STATE.polled
    _STATE.polled = True
    try:
        yield
    finally:
        _STATE.polled = before


def acting_on_stop() -> None:
    """The session caught the stop and finishes its saves: later stop signals only say so."""
    if _STATE.depth:
        _STATE.handled = True


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """While inside, SIGINT and SIGTERM raise `Stopped` in the main thread until the session acts on
    the stop (`acting_on_stop`); later ones, until the process exits, only say that the saves are
    being finished. SDL, which turns SIGTERM into a quit event that a headless session never reads,
    is told to leave signals alone."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    outermost = _STATE.depth == 0
    if outermost:
        _STATE.requested, _STATE.handled = None, False
    old = {s: signal.signal(s, _stop) for s in STOP_SIGNALS}
    if outermost:
        _STATE.hook, sys.unraisablehook = sys.unraisablehook, _dropped
    _STATE.depth += 1
    try:
        with environ(overwrite=True, SDL_NO_SIGNAL_HANDLERS="1"):  # read when pygame starts SDL
            yield
    finally:
        _STATE.depth -= 1
        if outermost:
            sys.unraisablehook = _STATE.hook
            for timer in _STATE.timers:
                timer.cancel()
            _STATE.timers.clear()
        if _STATE.requested is None:
            # After a stop the handlers stay: the process is on its way out, and a second Ctrl-C
            # arriving while it prints the summary or exits would otherwise end it with a traceback.
            for s, handler in old.items():
                signal.signal(s, handler)


@contextlib.contextmanager
def signals_held(message: str | None) -> Iterator[list[int]]:
    """While inside, SIGINT and SIGTERM are noted (and `message`, if any, printed) instead of interrupting:
    the saves that a first Ctrl-C asked to finish are not abandoned by a second one."""
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def note(signum: int, frame: FrameType | None) -> None:
        received.append(signum)
        if message is not None:
            os.write(2, f"{message}\n".encode())

    old = {s: signal.signal(s, note) for s in STOP_SIGNALS}
    try:
        yield received
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


@contextlib.contextmanager
def stops_deferred() -> Iterator[None]:
    """While inside, a stop signal waits and is delivered again once out (to whatever handles it then), so
    that a short piece of bookkeeping runs whole: a pool's workers all stopped, or a new worker recorded
    as the pool's (Python runs a signal's handler in the main thread even where that thread blocks the
    signal, as another thread takes it). Only in the main thread, where Python runs handlers."""
    received: list[int] = []
    try:
        with signals_held(None) as held:
            received = held
            yield
    finally:  # the handlers are back: each stop once, as if it came now
        for signum in dict.fromkeys(received):
            signal.raise_signal(signum)
