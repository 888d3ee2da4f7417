"""The scripted device: events from a JSON file, one per control tick (collect_fetch_demo.py's test device)."""

from __future__ import annotations

import dataclasses
import json
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from fetch.errors import FetchError
from fetch.teleop.devices import Command, DeviceContext, DeviceKind, idle

BUILTIN_IDLE_STEPS = 10
"""collect_fetch_demo.py's built-in pattern (no --scripted-json): this many idle steps, then discard the attempt."""

SCRIPT_FORMAT = f"""\
A JSON list of events (numbered from 0), one per control tick. {{"action": [dx, dy, dz, gripper]}}
steps the arm (each number in [-1, 1], clipped; dx, dy, dz move the hand, gripper > 0 opens it and
< 0 closes it; a missing "action" is [0, 0, 0, 0]). Flags, false when missing: "finish": true ends
the attempt after that step and keeps it if it succeeded (with --keep-failures, also if not);
"discard": true (or "reset": true, its name in collect_fetch_demo.py) ends the attempt and drops it, without stepping;
"quit": true ends the session, without stepping (the attempt in progress is kept only if it had
already succeeded). One list serves the whole session: it does not restart at each attempt, so an
attempt that ends by success, --max-steps or a discard leaves the events after it to the next
attempt (the run prints where each attempt starts); when the list runs out, the session quits.
Without --scripted-json: a built-in test pattern ({BUILTIN_IDLE_STEPS} idle steps, then discard), which saves
nothing (unless --keep-failures with --max-steps under {BUILTIN_IDLE_STEPS})."""
"""The `--scripted-json` format, as the CLI's help and docs/collecting.md state it."""


class ScriptedDevice:
    """Events from a list (`SCRIPT_FORMAT`), one per tick, across attempts; when it runs out, the session quits.

    `log`, when given, is told where each attempt starts in the list and when the list has run out.
    """

    name = "scripted"

    def __init__(self, events: Sequence[Command], log: Callable[[str], None] | None = None) -> None:
        self.events = list(events)
        self.index = 0
        self.log = log

    def reset(self) -> None:
        if self.log is None:
            return
        if self.index < len(self.events):
            self.log(f"scripted: next attempt starts at event {self.index} (of 0..{len(self.events) - 1})")
        else:
            self.log(f"scripted: all {len(self.events)} events used; quitting")

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        if self.index >= len(self.events):
            return Command(idle(), quit=True)
        self.index += 1
        return self.events[self.index - 1]

    def close(self) -> None:
        pass


_FLAGS = ("reset", "discard", "finish", "quit")
_EVENT_KEYS = {"action", *_FLAGS}


def load_script(path: str | os.PathLike[str]) -> list[Command]:
    """The events of a `--scripted-json` file (`SCRIPT_FORMAT`); FetchError naming the file and the event."""
    try:
        with open(path, encoding="utf-8") as f:
            raw = json.load(f)
    except OSError as e:
        raise FetchError(f"cannot read the scripted events file {path}: {e.strerror}") from e
    except json.JSONDecodeError as e:
        raise FetchError(f"{path} is not valid JSON: {e.msg} at line {e.lineno} column {e.colno}") from e
    if not isinstance(raw, list):
        raise FetchError(f"{path} must hold a JSON list of events, not a {type(raw).__name__}")
    events = []
    for i, item in enumerate(raw):
        where = f"{path}: event {i}"
        if not isinstance(item, dict):
            raise FetchError(f"{where} must be an object like {{\"action\": [0, 0, 0, 0]}}, got {item!r}")
        unknown = set(item) - _EVENT_KEYS
        if unknown:
            raise FetchError(f"{where} has unknown keys {sorted(unknown)}; valid: {sorted(_EVENT_KEYS)}")
        action = item.get("action", [0.0, 0.0, 0.0, 0.0])
        try:
            vector = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            vector = np.empty(0)
        if vector.shape != (4,) or not np.all(np.isfinite(vector)):
            raise FetchError(f"{where}: \"action\" must be 4 finite numbers (dx, dy, dz, gripper), got {action!r}")
        for flag in _FLAGS:
            if item.get(flag, False) not in (True, False):  # also 0 and 1; not "no", which would be true
                raise FetchError(f"{where}: \"{flag}\" must be true or false, got {item[flag]!r}")
        events.append(Command(vector.astype(np.float32),  # the env clips it
                              discard=bool(item.get("reset", False) or item.get("discard", False)),
                              finish=bool(item.get("finish", False)), quit=bool(item.get("quit", False))))
    return events


def builtin_notice(keep_failures: bool, max_steps: int) -> str:
    """What the collector says, once, when --device scripted runs without --scripted-json."""
    saves = ("keeps the attempts --max-steps cuts short as failed demos" if keep_failures
             and max_steps < BUILTIN_IDLE_STEPS else "saves nothing")
    return (f"no --scripted-json: running the built-in test pattern ({BUILTIN_IDLE_STEPS} idle steps, then discard "
            f"the attempt; then the events run out and the session quits), which {saves}; "
            "--scripted-json FILE drives the arm (format: gym-fetch collect --help)")


def default_script() -> list[Command]:
    """collect_fetch_demo.py's built-in pattern: `BUILTIN_IDLE_STEPS` idle ticks, then end and discard the attempt."""
    return [Command(idle()) for _ in range(BUILTIN_IDLE_STEPS)] + [Command(idle(), discard=True)]


@dataclasses.dataclass(frozen=True)
class ScriptedOptions:
    """The scripted device's flag."""

    scripted_json: str | None = None
    """the events' file (`SCRIPT_FORMAT`); None: the built-in test pattern."""


def add_scripted_arguments(p: Any) -> None:
    p.add_argument("--scripted-json", default=None, metavar="FILE", help=SCRIPT_FORMAT)


def build_scripted(context: DeviceContext) -> ScriptedDevice:
    path = context.options_for(ScriptedOptions).scripted_json
    if path:
        events = load_script(path)
        print(f"scripted: {len(events)} events from {path}, one per control tick; the list runs "
              "on across attempts and the session quits when it runs out", file=sys.stderr)
    else:
        events = default_script()
        print(builtin_notice(context.keep_failures, context.max_steps), file=sys.stderr)
    return ScriptedDevice(events, log=lambda text: print(text, flush=True))


KIND = DeviceKind(
    name="scripted", human=False, legend=(), add_arguments=add_scripted_arguments, options=ScriptedOptions,
    summary="events from --scripted-json, one per tick (a test device; no person)",
    build=build_scripted)
