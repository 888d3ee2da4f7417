"""A person's time and undo, through the real pad path (SDL virtual pad): the attempt's clock waits for the
first input, and BACK rewinds a second (held: more), leaving out of the saved demo what was rewound."""

from __future__ import annotations

import pathlib
from collections.abc import Mapping

import numpy as np

import vpad  # fetch.testing.vpad, re-exported by tests/vpad.py
from fetch.dataset import open_dataset, validate
from fetch.dataset.replay.check import check_demo
from fetch.teleop.devices import REWIND_REPEAT, REWIND_STEPS, Command
from fetch.teleop.gamepad import GamepadConfig, GamepadDevice
from fetch.teleop.session import CollectConfig, Session

IDLE = 6
"""Ticks the operator reads the window before touching the pad."""


class Rewinder:
    """Waits, drives the hand away from the goal, rewinds with a press, drives away again, rewinds by holding
    BACK through one repeat, then drives to the goal. Checks what the session does at each tick."""

    name = "gamepad"

    def __init__(self, pad: vpad.VirtualPad, device: GamepadDevice) -> None:
        self.pad, self.device = pad, device
        self.session: Session | None = None
        self.tick = 0
        self.start: np.ndarray | None = None
        self.lengths: list[int] = []
        self.gripper_closed_after_rewind: list[bool] = []

    def reset(self) -> None:
        self.device.reset()
        self.tick = 0

    def _away(self, obs: Mapping[str, np.ndarray]) -> None:
        x, y, z = np.clip((obs["achieved_goal"] - obs["desired_goal"]) / 0.05, -1, 1)
        self.pad.set_stick(float(x), float(-y))

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        assert self.session is not None
        self.tick += 1
        t = self.tick
        self.lengths.append(self.session.buffer.length)
        if t == 1:
            self.start = self.session.base.get_state()
        if t <= IDLE:  # reading the legend: the arm must not have moved, the clock not run
            assert self.session.buffer.length == 0
            assert np.array_equal(self.session.base.get_state(), self.start)
        elif t <= IDLE + 30:  # the wrong way, and the gripper closed half way
            self._away(obs)
            if t == IDLE + 15:
                self.pad.press("x")
            elif t == IDLE + 16:
                self.pad.release("x")
        elif t == IDLE + 31:  # 30 steps taken: one press takes back 25 (to before the gripper closed)
            self.pad.set_stick(0.0, 0.0)
            self.pad.press("back")
        elif t == IDLE + 32:
            self.pad.release("back")
        elif t <= IDLE + 42:  # 5 + 10 steps: a long press goes back twice, to the start
            self._away(obs)
        elif t <= IDLE + 43 + REWIND_REPEAT:
            self.pad.set_stick(0.0, 0.0)
            self.pad.press("back")
        elif t == IDLE + 44 + REWIND_REPEAT:
            self.pad.release("back")
        else:
            x, y, z = np.clip((obs["desired_goal"] - obs["achieved_goal"]) / 0.05, -1, 1)
            self.pad.set_stick(float(x), float(-y))
            self.pad.set_triggers(max(0.0, -float(z)), max(0.0, float(z)))
        return self.device.poll(obs)

    def gripper_from(self, action: np.ndarray | None) -> None:
        self.device.gripper_from(action)
        self.gripper_closed_after_rewind.append(self.device.mapper.gripper_closed)

    def close(self) -> None:
        self.device.close()


def test_the_clock_waits_and_rewinds_leave_out_what_was_taken_back(pad: vpad.VirtualPad,
                                                                   tmp_path: pathlib.Path) -> None:
    config = CollectConfig(env_id="Reach-v2", out=str(tmp_path), device="gamepad", render="none", control_hz=0,
                           success_hold_steps=3, max_steps=200, episodes=1)
    operator = Rewinder(pad, GamepadDevice(GamepadConfig(deadzone=0.02)))
    session = Session(config, operator, log=lambda text: None)
    operator.session = session
    summary = session.run()
    attempt = summary.attempts[0]
    assert attempt.ended_by == "success" and attempt.saved_as == "demo_0"
    lengths = operator.lengths
    # lengths[i]: steps kept when tick i + 1 began. The first step came with the first input; the press took
    # 30 steps back to 5; the clock then ran on (11 steps, the release's tick one of them); the held press
    # took those 16 back to the start, the arm waited while it was held, and the repeat found nothing left.
    assert lengths[IDLE] == 0 and lengths[IDLE + 1] == 1
    assert lengths[IDLE + 30] == 30 and lengths[IDLE + 31] == 30 - REWIND_STEPS
    assert lengths[IDLE + 42] == 16 and lengths[IDLE + 43] == 0 and lengths[IDLE + 43 + REWIND_REPEAT] == 0
    assert attempt.rewound == REWIND_STEPS + 16
    # Rewound to before the gripper closed: the toggle opened again (no jump of the fingers at the next step).
    assert operator.gripper_closed_after_rewind[0] is False
    with open_dataset(tmp_path) as ds:
        assert validate(ds) == []
        demo = ds.demo("demo_0")
        assert demo.attrs["num_samples"] == attempt.steps == lengths[-1] + 1
        actions = demo["actions"][()]
        # Only the path that was kept: from the start, straight to the goal, the gripper never closed.
        assert (actions[:, 3] == 1.0).all()
        check = check_demo(ds, "demo_0")
        assert check.exact, check.largest


def test_a_held_rewind_repeats_and_a_press_rewinds_once() -> None:
    from fetch.teleop.devices import HandControls

    controls = HandControls()
    held = [controls.command((0, 0, 0), {"rewind"}, False, rewinding=True).rewind]
    held += [controls.command((0, 0, 0), set(), False, rewinding=True).rewind for _ in range(2 * REWIND_REPEAT)]
    assert [i for i, r in enumerate(held) if r] == [0, REWIND_REPEAT, 2 * REWIND_REPEAT]
    assert all(r in (0, REWIND_STEPS) for r in held)
    assert controls.command((0, 0, 0), set(), False, rewinding=False).rewind == 0
    assert controls.command((0, 0, 0), set(), False, rewinding=True).rewind == 0, "held without a new press"
    assert not controls.command((1, 0, 0), set(), False, rewinding=True).paused, "nor does it hold the arm"
