"""What drives the arm during collection: the device interface and the declaration each device makes.

A device is polled once per control tick for a `Command`. Each kind of device declares itself once,
as a `DeviceKind` beside its code (its name, whether a person drives it, its legend, its flags and
how to build it); `fetch.teleop.registry` lists them, and the CLI, the session and the viewer read
only that list. A device never sees the command line: its flags arrive as its own typed options
(`DeviceKind.options`), in the `DeviceContext` it is built with.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Collection, Mapping
from typing import Any, Protocol, TypeVar

import numpy as np


@dataclasses.dataclass(frozen=True)
class Command:
    """One tick's input: the 4-D action (the env clips it to [-1, 1]) and the episode events.

    `discard` ends the attempt and drops it; `finish` ends it and keeps it if it succeeded;
    `quit` ends the session; `paused` (e.g. a pad unplugged) holds the arm without stepping;
    `switch_camera` asks the viewer for the next camera; `precision` says slow mode is on (HUD);
    `rewind` takes the attempt back that many steps (the person's undo; a device that sends it has a
    `gripper_from(action)` method, told the last action kept so its gripper toggle matches the fingers);
    `gripper_closed` is the state a device with a gripper toggle holds (None: read from the
    action's sign, for devices that send a[3] directly). `label` is the action the device meant when
    the one it sends is deliberately perturbed (the expert under DART noise): it is recorded beside the
    executed action as the demo's `expert_actions`, the target a policy learns.
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
    gripper_closed: bool | None = None
    label: np.ndarray | None = None
    rewind: int = 0
    intervention: bool | None = None
    """For a device where a person can take the wheel from a policy: whether the person drove this step
    (recorded as the demo's `intervention`); None for other devices."""
    proposal: np.ndarray | None = None
    """... and what the policy proposed for this step (recorded as `policy_actions`)."""
    touched: bool = False
    """A person's input this tick: motion past the dead zone, the gripper toggled, or a rewind (what
    takes the arm over from a policy)."""

    @property
    def closes_gripper(self) -> bool:
        """Whether this command has the fingers closed (what the HUD shows)."""
        if self.gripper_closed is not None:
            return self.gripper_closed
        return bool(self.action[3] < 0)

    @property
    def acts(self) -> bool:
        """Whether this command does something to the scene: moves the hand, closes the fingers, or ends
        the attempt keeping it (what starts a person's clock)."""
        return bool(np.any(self.action[:3] != 0)) or self.closes_gripper or self.finish


def idle() -> np.ndarray:
    return np.zeros(4, np.float32)


def rotate(x: float, y: float, yaw: float) -> tuple[float, float]:
    """(x, y) turned by `yaw` [rad] counter-clockwise: input in the viewer's frame to the world's."""
    c, s = math.cos(yaw), math.sin(yaw)
    return c * x - s * y, s * x + c * y


REWIND_STEPS = 25
"""Steps one rewind takes back: a second at the person's 25 Hz."""
REWIND_REPEAT = 12
"""[ticks] while the rewind control stays held, it takes another `REWIND_STEPS` back this often (about
twice a second), so holding it runs the attempt backwards."""


@dataclasses.dataclass
class HandControls:
    """The part that a pad and a keyboard share: a gripper toggled by presses, one-shot events, a
    precision mode, rewind. `command` turns one tick's motion and presses into a `Command`."""

    gripper_open: float = 1.0
    gripper_close: float = -1.0
    precision_scale: float = 0.3
    gripper_closed: bool = False
    _rewind_held: int = 0

    def reset(self) -> None:
        """A new attempt: the gripper opens."""
        self.gripper_closed = False
        self._rewind_held = 0

    def gripper_from(self, action: np.ndarray | None) -> None:
        """The hand is where `action` left it (None: an attempt's start), after a rewind or while something
        else drove it: the gripper toggle takes the state that action had, so the fingers do not jump at
        the next step."""
        self.gripper_closed = action is not None and \
            abs(float(action[3]) - self.gripper_close) < abs(float(action[3]) - self.gripper_open)

    def command(self, motion: tuple[float, float, float], pressed: Collection[str], precision: bool,
                scale: float = 1.0, rewinding: bool = False) -> Command:
        """`motion` (dx, dy, dz, world frame, each in [-1, 1] at full input) times `scale` (and the
        precision scale while `precision` is held); `pressed`: the roles pressed since the last tick
        ("gripper", "discard", "finish", "quit", "camera", "rewind"); `rewinding`: the rewind control is
        held now (a press rewinds `REWIND_STEPS`, and so does every `REWIND_REPEAT`-th tick it stays held;
        the ticks between pause the arm)."""
        if "gripper" in pressed:
            self.gripper_closed = not self.gripper_closed
        rewind = 0
        if "rewind" in pressed:
            self._rewind_held, rewind = 1, REWIND_STEPS
        elif rewinding and self._rewind_held:
            self._rewind_held += 1
            rewind = REWIND_STEPS if self._rewind_held % REWIND_REPEAT == 1 else 0
        else:
            self._rewind_held = 0
        holding = self._rewind_held > 0  # between a held rewind's jumps the arm waits: nothing is recorded
        scale *= self.precision_scale if precision else 1.0
        gripper = self.gripper_close if self.gripper_closed else self.gripper_open
        action = np.array([motion[0] * scale, motion[1] * scale, motion[2] * scale, gripper], np.float32)
        return Command(action, discard="discard" in pressed, finish="finish" in pressed, quit="quit" in pressed,
                       switch_camera="camera" in pressed, precision=precision,
                       status="rewinding" if holding else "precision" if precision else "",
                       gripper_closed=self.gripper_closed, rewind=rewind, paused=holding,
                       touched=any(motion) or "gripper" in pressed or rewinding or bool(rewind))


class Device(Protocol):
    """A source of commands; pygame and other hardware imports happen inside the backends."""

    name: str

    def reset(self) -> None:
        """A new attempt starts (e.g. the gripper opens again, an expert restarts)."""

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        """The command for this tick; `obs` is the latest observation (only experts read it)."""
        ...

    def close(self) -> None: ...


FRAMES = ("camera", "world")
"""Which way a person's input steers: "camera", 'up' moves away from the viewer (the view's yaw); "world", up
is the world's +y whatever the view."""

Options = TypeVar("Options")


def options_in(given: Collection[object], kind: type[Options]) -> Options:
    """The options of type `kind` (a `DeviceKind.options`) among those `given`, else its defaults."""
    for options in given:
        if isinstance(options, kind):
            return options
    return kind()


@dataclasses.dataclass(frozen=True)
class DeviceContext:
    """What a device may need when it is built: the session's env, the window if there is one, the yaw of
    the view to steer in (None: the world's axes), the session settings a device reads, and each device's
    own options (`DeviceKind.options`; `options_for` finds one)."""

    env: Any
    viewer: Any | None
    yaw: Callable[[], float] | None
    seed: int = 0
    """attempt k of the dataset resets with seed + k."""
    max_steps: int = 0
    """[steps] the longest attempt, as the session decided it."""
    keep_failures: bool = False
    """failed attempts are saved too."""
    options: tuple[object, ...] = ()
    """the devices' options given (one object per kind at most; a kind's left out has its defaults)."""

    def options_for(self, kind: type[Options]) -> Options:
        """The options of type `kind` (a `DeviceKind.options`) given, else its defaults."""
        return options_in(self.options, kind)


@dataclasses.dataclass(frozen=True)
class DeviceKind:
    """A kind of device, declared once beside its code and listed in `fetch.teleop.registry`.

    Every field is required and checked when the declaration runs (at import): a device that forgets
    one fails there, not silently in a session.
    """

    name: str
    """The `--device` value."""
    human: bool
    """A person drives it: the collector opens a window (when there is a display) and paces the arm
    at the env's real-time rate."""
    legend: tuple[str, ...]
    """The controls, one entry each ("Z: rewind 1 s"), as the viewer shows them, wrapped to its width
    (required when a person drives it)."""
    summary: str
    """One line for `--help`."""
    add_arguments: Callable[[Any], None] | None
    """Adds the device's own flags to a parser or group of the command layer (None: it has none); each flag's
    destination is a field of `options`."""
    build: Callable[[DeviceContext], Device]
    aliases: tuple[str, ...] = ()
    """Other `--device` values meaning this one ("xbox", collect_fetch_demo.py's name, is the gamepad)."""
    waits_for_input: bool = True
    """Where a person drives: an attempt's clock starts at their first input (False: something else drives
    from the start, as a policy the person corrects)."""
    legend_from: str = ""
    """The field of `options` (e.g. "takeover_with") naming another device whose legend the window shows after
    this one's: a device that a person drives through another."""
    reads_window: bool = False
    """It reads its input from the collection window (keys typed into it): without a window it cannot run, and
    the collector says so, in one line naming what works, before anything opens."""
    holds_past_success: bool = False
    """Unless `--stop-on-success` is given, an attempt runs on to the task's horizon (the default
    `--max-steps`) instead of ending once success has held: a demo that shows holding the goal
    teaches a policy more (docs/results/learning_curves.md), and costs no one's time when no person drives."""
    options: type[Any] | None = None
    """The frozen dataclass of the device's own flags, one field per flag (named as its destination:
    `--expert-noise` is `expert_noise`), every field with a default; what `build` reads through
    `DeviceContext.options_for`. None: it has no flags."""

    def __post_init__(self) -> None:
        where = f"device {self.name!r}"
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise TypeError(f"a DeviceKind's name must be a word like 'gamepad', got {self.name!r}")
        if not isinstance(self.human, bool):
            raise TypeError(f"{where}: human must be True or False, got {self.human!r}")
        if not isinstance(self.legend, tuple) or not all(isinstance(line, str) for line in self.legend):
            raise TypeError(f"{where}: legend must be a tuple of strings, got {self.legend!r}")
        if self.human and not self.legend:
            raise TypeError(f"{where}: a person drives it, so it needs a legend (the controls the viewer shows)")
        if not isinstance(self.summary, str) or not self.summary:
            raise TypeError(f"{where}: summary must be a line for --help, got {self.summary!r}")
        if self.add_arguments is not None and not callable(self.add_arguments):
            raise TypeError(f"{where}: add_arguments must be a function or None, got {self.add_arguments!r}")
        if not isinstance(self.waits_for_input, bool):
            raise TypeError(f"{where}: waits_for_input must be True or False, got {self.waits_for_input!r}")
        if not isinstance(self.legend_from, str):
            raise TypeError(f"{where}: legend_from must be an argument's name or '', got {self.legend_from!r}")
        if not isinstance(self.reads_window, bool):
            raise TypeError(f"{where}: reads_window must be True or False, got {self.reads_window!r}")
        if not isinstance(self.holds_past_success, bool):
            raise TypeError(f"{where}: holds_past_success must be True or False, got {self.holds_past_success!r}")
        if not callable(self.build):
            raise TypeError(f"{where}: build must be a function of a DeviceContext, got {self.build!r}")
        if self.options is not None:
            if not (isinstance(self.options, type) and dataclasses.is_dataclass(self.options)):
                raise TypeError(f"{where}: options must be a dataclass of its flags, got {self.options!r}")
            self.options()  # every field has a default: a session that gives none builds the device as documented
        if (self.add_arguments is None) != (self.options is None):
            raise TypeError(f"{where}: add_arguments (its flags) and options (what they are read into) go together")
        if self.legend_from and (self.options is None
                                 or self.legend_from not in {f.name for f in dataclasses.fields(self.options)}):
            raise TypeError(f"{where}: legend_from must name a field of its options, got {self.legend_from!r}")
