"""What drives the arm during collection: a device is polled once per control tick for a `Command`."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping, Sequence
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


class ScriptedDevice:
    """The seed's JSON event list, one event per tick; when it runs out, the session quits."""

    name = "scripted"

    def __init__(self, events: Sequence[Command]) -> None:
        self.events = list(events)
        self.index = 0

    def reset(self) -> None:
        pass

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        if self.index >= len(self.events):
            return Command(idle(), quit=True)
        self.index += 1
        return self.events[self.index - 1]

    def close(self) -> None:
        pass


_EVENT_KEYS = {"action", "reset", "discard", "finish", "quit"}


def load_script(path: str | os.PathLike[str]) -> list[Command]:
    """Events from a JSON list of `{"action": [4 numbers], "reset": bool, "quit": bool}` (the seed's
    format; "reset" ends and discards the attempt, as its Y button; "finish" ends and keeps it)."""
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
        events.append(Command(np.clip(vector, -1.0, 1.0).astype(np.float32),
                              discard=bool(item.get("reset", False) or item.get("discard", False)),
                              finish=bool(item.get("finish", False)), quit=bool(item.get("quit", False))))
    return events


def default_script() -> list[Command]:
    """The seed's default scripted pattern: 10 idle ticks, then end the attempt."""
    return [Command(idle()) for _ in range(10)] + [Command(idle(), discard=True)]
