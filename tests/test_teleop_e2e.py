"""End to end through SDL: a virtual Xbox pad drives `gym-fetch collect`'s loop; Y discards, START quits."""

from __future__ import annotations

import pathlib
from collections.abc import Mapping

import numpy as np

import vpad  # fetch.testing.vpad, re-exported by tests/vpad.py
from fetch.dataset import open_dataset, validate
from fetch.teleop.devices import Command
from fetch.teleop.gamepad import GamepadConfig, GamepadDevice
from fetch.teleop.session import CollectConfig, Session


class Operator:
    """Moves the virtual pad's stick and buttons as a person would, then lets the real device read it."""

    name = "gamepad"

    def __init__(self, pad: vpad.VirtualPad, device: GamepadDevice) -> None:
        self.pad, self.device = pad, device
        self.attempt = -1
        self.tick = 0
        self.pressed: str | None = None

    def reset(self) -> None:
        self.device.reset()
        self.attempt += 1
        self.tick = 0

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        if self.pressed:
            self.pad.release(self.pressed)
            self.pressed = None
        self.tick += 1
        if self.attempt == 0 and self.tick == 4:
            self._press("y")  # give up on the first attempt
        elif self.attempt == 2:
            self._press("start")  # done for the day
        else:  # steer towards the goal: x right, y up (SDL's y axis points down)
            delta = (obs["desired_goal"] - obs["achieved_goal"]) / 0.05
            x, y, z = np.clip(delta, -1, 1)
            self.pad.set_stick(float(x), float(-y))
            self.pad.set_triggers(max(0.0, -float(z)), max(0.0, float(z)))
        return self.device.poll(obs)

    def _press(self, button: str) -> None:
        self.pad.press(button)
        self.pressed = button

    def close(self) -> None:
        self.device.close()


def test_a_virtual_pad_records_a_successful_demo(pad: vpad.VirtualPad, tmp_path: pathlib.Path) -> None:
    config = CollectConfig(env_id="Reach-v2", out=str(tmp_path), device="gamepad", render="none",
                           control_hz=0, success_hold_steps=3, max_steps=100)
    operator = Operator(pad, GamepadDevice(GamepadConfig(deadzone=0.02)))
    summary = Session(config, operator, log=lambda text: None).run()
    ended = [a.ended_by for a in summary.attempts]
    assert ended == ["discard", "success", "quit"], ended
    assert summary.saved == 1 and summary.total_saved == 1
    with open_dataset(tmp_path) as ds:
        assert ds.demo_names == ["demo_0"] and validate(ds) == []
        demo = ds.demo("demo_0")
        assert bool(demo.attrs["success"]) and demo.attrs["device"] == "gamepad"
        assert int(demo.attrs["attempt"]) == 1 and demo["is_success"][-3:].all()
        actions = demo["actions"][()]
        assert np.abs(actions[:, :3]).max() > 0.3, "the stick moved the arm"
        assert (actions[:, 3] == 1.0).all(), "the gripper stayed open (X never pressed)"
