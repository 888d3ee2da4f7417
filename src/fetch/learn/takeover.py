"""A person corrects a running policy (`gym-fetch collect --device takeover --policy RUN`): the policy
drives, any input from the pad (or the window's keyboard) hands the arm to the person at once, and
after the person has let go for `HAND_BACK` the policy drives again. Every step records who drove
(`intervention`) and what the policy proposed (`policy_actions`): the labels HG-DAgger-style training
learns from. Declared here and registered with the collector's devices, as the policy device is.

Actions are moves of the hand relative to where it is, so nothing jumps at a switch: the hand goes on
from wherever the other driver left it, and the person's gripper toggle follows the policy's
fingers while the policy drives, so taking over does not open or close them.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from fetch.errors import FetchError
from fetch.learn.device import PolicyDevice, PolicyOptions
from fetch.teleop.devices import Command, Device, DeviceContext, DeviceKind
from fetch.teleop.registry import device_kind, register

HAND_BACK = 12
"""[ticks] the person's hands off the controls this long (about half a second at 25 Hz) gives the arm
back to the policy: long enough to pass between two pushes of the stick, short enough that a person
who has put things right need not wait."""
PEOPLE = ("gamepad", "keyboard")
"""The devices a person takes over with."""


class TakeoverDevice:
    """A policy that drives until a person's device reports input (motion past its dead zone, the gripper
    toggled, a rewind), then the person until `hand_back` ticks without input. `takeovers` counts the
    times the person took over in this attempt; `driver` is who drives now ("policy" or "person")."""

    name = "takeover"

    def __init__(self, policy: Device, person: Device, hand_back: int = HAND_BACK) -> None:
        if hand_back < 1:
            raise FetchError(f"the hand-back time must be at least one tick, got {hand_back}")
        self.policy, self.person, self.hand_back = policy, person, hand_back
        self.driver = "policy"
        self.takeovers = 0
        self._idle = 0
        self._last_policy: np.ndarray | None = None

    def reset(self) -> None:
        self.policy.reset()
        self.person.reset()
        self.driver, self.takeovers, self._idle, self._last_policy = "policy", 0, 0, None

    def gripper_from(self, action: np.ndarray | None) -> None:
        """After a rewind: the person's gripper toggle takes the fingers' state there, and the policy starts
        its memory afresh (what it remembered is of steps that are gone)."""
        follow = getattr(self.person, "gripper_from", None)
        if follow is not None:
            follow(action)
        self.policy.reset()

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        # The policy is asked every tick, driving or not: its memory (action chunks, recurrent state) stays
        # in step with the episode, and its proposal is recorded where the person drives.
        proposed = self.policy.poll(obs)
        proposal = np.asarray(proposed.action, np.float32)
        follow = getattr(self.person, "gripper_from", None)
        if self.driver == "policy" and follow is not None:
            follow(self._last_policy)  # the toggle where the policy has the fingers
        command = self.person.poll(obs)
        if command.touched:
            if self.driver == "policy":
                self.takeovers += 1
            self.driver, self._idle = "person", 0
        elif self.driver == "person" and not command.paused:
            self._idle += 1
            if self._idle >= self.hand_back:
                self.driver = "policy"
        person = self.driver == "person"
        action = np.asarray(command.action, np.float32) if person else proposal
        if not person:
            self._last_policy = proposal
        driver = f"{'YOU drive' if person else 'the policy drives'}   takeovers {self.takeovers}"
        status = "   ".join(filter(None, (driver, proposed.status, command.status)))  # proposed: how unsure it is
        return Command(action, discard=command.discard, finish=command.finish, quit=command.quit,
                       paused=command.paused, switch_camera=command.switch_camera, precision=command.precision,
                       status=status, rewind=command.rewind,
                       gripper_closed=command.gripper_closed if person else bool(proposal[3] < 0),
                       intervention=person, proposal=proposal)

    def close(self) -> None:
        self.person.close()
        self.policy.close()


@dataclasses.dataclass(frozen=True)
class TakeoverOptions:
    """The takeover device's flag (its policy is the policy device's --policy: `PolicyOptions`)."""

    takeover_with: str = "gamepad"
    """the device the person takes over with (`PEOPLE`)."""


def add_takeover_arguments(p: Any) -> None:
    p.add_argument("--takeover-with", default="gamepad", choices=PEOPLE,
                   help="with --device takeover: what the person takes over with (default gamepad; keyboard: "
                        "in the window)")


def build_takeover(context: DeviceContext) -> Device:
    run = context.options_for(PolicyOptions).policy
    if not run:
        raise FetchError("--device takeover needs --policy RUN (a directory written by `gym-fetch train`)")
    with contextlib.ExitStack() as undo:  # closes what was opened if a later part fails
        policy = PolicyDevice(context.env, run)  # first: a run that cannot be used is refused before a pad is sought
        undo.callback(policy.close)
        person = device_kind(context.options_for(TakeoverOptions).takeover_with).build(context)
        undo.callback(person.close)
        device = TakeoverDevice(policy, person)
        undo.pop_all()
    return device


KIND = register(DeviceKind(
    name="takeover", human=True, add_arguments=add_takeover_arguments, options=TakeoverOptions,
    build=build_takeover,
    summary="a trained policy (--policy RUN) that you correct: any input takes over, let go to hand back",
    legend_from="takeover_with", waits_for_input=False,
    legend=("the policy drives: any input takes over", "let go 0.5 s: it drives again")))
