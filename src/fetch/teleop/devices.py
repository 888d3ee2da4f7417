"""What drives the arm during collection: a device is polled once per control tick for a `Command`."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from fetch.errors import FetchError

DEVICES = ("gamepad", "keyboard", "scripted", "expert")
"""Valid `--device` choices; "xbox" (the seed's name) means "gamepad"."""


@dataclasses.dataclass(frozen=True)
class Command:
    """One tick's input: the 4-D action in [-1, 1] and the episode events.

    `discard` ends the attempt and drops it; `finish` ends it and keeps it if it succeeded;
    `quit` ends the session; `paused` (e.g. a pad unplugged) holds the arm without stepping;
    `switch_camera` asks the viewer for the next camera; `precision` says slow mode is on (HUD).
    """

    action: np.ndarray
    discard: bool = False
    finish: bool = False
    quit: bool = False
    paused: bool = False
    switch_camera: bool = False
    precision: bool = False
    status: str = ""
    """A short line for the HUD (e.g. "precision", "pad disconnected")."""


def idle() -> np.ndarray:
    return np.zeros(4, np.float32)


def rotate(x: float, y: float, yaw: float) -> tuple[float, float]:
    """(x, y) turned by `yaw` [rad] counter-clockwise: input in the viewer's frame to the world's."""
    c, s = math.cos(yaw), math.sin(yaw)
    return c * x - s * y, s * x + c * y


class Device(Protocol):
    """A source of commands; pygame and other hardware imports happen inside the backends."""

    name: str

    def reset(self) -> None:
        """A new attempt starts (e.g. the gripper opens again, an expert restarts)."""

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        """The command for this tick; `obs` is the latest observation (only experts read it)."""
        ...

    def close(self) -> None: ...


class ExpertDevice:
    """The task's scripted expert as a device: datasets with no person."""

    name = "expert"

    def __init__(self, env: Any) -> None:
        from fetch.experts import make_expert

        self.expert = make_expert(env)

    def reset(self) -> None:
        self.expert.reset()

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        return Command(np.asarray(self.expert(obs), dtype=np.float32))

    def close(self) -> None:
        pass


BUILTIN_IDLE_STEPS = 10
"""The seed's built-in pattern (no --scripted-json): this many idle steps, then discard the attempt."""

SCRIPT_FORMAT = f"""\
A JSON list of events (numbered from 0), one per control tick. {{"action": [dx, dy, dz, gripper]}}
steps the arm (each number in [-1, 1], clipped; dx, dy, dz move the hand, gripper > 0 opens it and
< 0 closes it; a missing "action" is [0, 0, 0, 0]). Flags, false when missing: "finish": true ends
the attempt after that step and keeps it if it succeeded (with --keep-failures, also if not);
"discard": true (or the seed's "reset": true) ends the attempt and drops it, without stepping;
"quit": true ends the session, without stepping (the attempt in progress is kept only if it had
already succeeded). One list serves the whole session: it does not restart at each attempt, so an
attempt that ends by success, --max-steps or a discard leaves the events after it to the next
attempt (the run prints where each attempt starts); when the list runs out, the session quits.
Without --scripted-json: a built-in test pattern ({BUILTIN_IDLE_STEPS} idle steps, then discard), which saves
nothing (unless --keep-failures with --max-steps under {BUILTIN_IDLE_STEPS})."""
"""The `--scripted-json` format, as the CLI's help and the README state it."""


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
        events.append(Command(np.clip(vector, -1.0, 1.0).astype(np.float32),
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
    """The seed's built-in pattern: `BUILTIN_IDLE_STEPS` idle ticks, then end and discard the attempt."""
    return [Command(idle()) for _ in range(BUILTIN_IDLE_STEPS)] + [Command(idle(), discard=True)]
