"""The gamepad: the pure mapping from pad snapshots to commands, profiles, and the real device on a virtual pad."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np
import pygame
import pytest

import fetch  # noqa: F401  (registers the ids)
import vpad
from fetch.commands import gamepad as gamepad_command
from fetch.commands.flags import options_of
from fetch.errors import FetchError
from fetch.teleop.devices import Command
from fetch.teleop.gamepad import (
    DISCONNECTED,
    GamepadConfig,
    GamepadDevice,
    Mapper,
    PadFlags,
    PadState,
    _Pad,
    calibrate,
    config_from_flags,
    radial_deadzone,
)

UP = -1.0  # SDL's stick y points down


def step(mapper: Mapper, *states: PadState, yaw: float = 0.0) -> list[Command]:
    return [mapper(s, yaw) for s in states]


# ---- the pure mapping ----


def test_radial_deadzone_is_round_continuous_and_reaches_full_tilt() -> None:
    assert radial_deadzone(0.07, 0.07, 0.1) == (0.0, 0.0)  # |v| = 0.099: inside the circle
    x, y = radial_deadzone(0.08, 0.08, 0.1)  # |v| = 0.113: outside, though each axis is below 0.1
    assert x > 0 and y > 0 and math.isclose(x, y)
    just_out = math.hypot(*radial_deadzone(0.1001, 0.0, 0.1))
    assert 0 < just_out < 1e-3  # no jump at the edge of the zone
    assert math.isclose(math.hypot(*radial_deadzone(0.6, -0.8, 0.1)), 1.0)
    mid = radial_deadzone(0.55, 0.0, 0.1)
    assert math.isclose(mid[0], 0.5)
    ox, oy = radial_deadzone(0.3, 0.4, 0.1)
    assert math.isclose(math.atan2(oy, ox), math.atan2(0.4, 0.3))  # direction kept


def test_stick_and_triggers_give_the_seed_world_mapping() -> None:
    mapper = Mapper(GamepadConfig())
    right, up, z_up, z_down = step(mapper, PadState(lx=1.0), PadState(ly=UP), PadState(rt=1.0), PadState(lt=1.0))
    np.testing.assert_allclose(right.action, [1, 0, 0, 1])
    np.testing.assert_allclose(up.action, [0, 1, 0, 1])
    np.testing.assert_allclose(z_up.action, [0, 0, 1, 1])
    np.testing.assert_allclose(z_down.action, [0, 0, -1, 1])
    assert right.action.dtype == np.float32
    (no_invert,) = step(Mapper(GamepadConfig(invert_y=False)), PadState(ly=UP))
    np.testing.assert_allclose(no_invert.action, [0, -1, 0, 1])


def test_action_is_scaled_and_only_the_env_clips_it() -> None:
    (half,) = step(Mapper(GamepadConfig(pos_scale=0.5)), PadState(lx=1.0, rt=1.0))
    np.testing.assert_allclose(half.action, [0.5, 0, 0.5, 1])
    (double,) = step(Mapper(GamepadConfig(pos_scale=2.0, deadzone=0.0)), PadState(lx=0.75, lt=1.0))
    np.testing.assert_allclose(double.action, [1.5, 0, -2, 1])  # the pad's command, unclipped
    # The env is the one place an action is clipped; what it applied is what a session records.
    env, clipped = gym.make("Reach-v2"), gym.make("Reach-v2")
    env.reset(seed=3)
    clipped.reset(seed=3)
    obs, *_ = env.step(double.action)
    np.testing.assert_array_equal(env.unwrapped.last_action, np.float32([1, 0, -1, 1]))
    expected, *_ = clipped.step(np.float32([1, 0, -1, 1]))
    np.testing.assert_array_equal(obs["observation"], expected["observation"])


def test_precision_scales_motion_while_held_not_the_gripper() -> None:
    mapper = Mapper(GamepadConfig(precision_scale=0.25))
    held, released = step(mapper, PadState(lx=1.0, rt=1.0, held=frozenset({"precision"})), PadState(lx=1.0))
    np.testing.assert_allclose(held.action, [0.25, 0, 0.25, 1])
    assert held.precision and held.status == "precision"
    np.testing.assert_allclose(released.action, [1, 0, 0, 1])
    assert not released.precision


def test_yaw_turns_stick_up_away_from_the_viewer() -> None:
    mapper = Mapper(GamepadConfig())
    # yaw = 90°: the viewer looks along world -x (fetch.teleop.viewer.camera_yaw), so "away" is -x
    up, right = step(mapper, PadState(ly=UP), PadState(lx=1.0), yaw=math.pi / 2)
    np.testing.assert_allclose(up.action, [-1, 0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(right.action, [0, 1, 0, 1], atol=1e-6)
    (behind,) = step(mapper, PadState(ly=UP), yaw=math.pi)
    np.testing.assert_allclose(behind.action, [0, -1, 0, 1], atol=1e-6)
    (z,) = step(mapper, PadState(rt=1.0), yaw=1.0)
    np.testing.assert_allclose(z.action, [0, 0, 1, 1], atol=1e-6)  # up stays up


def test_gripper_toggles_once_per_press_and_reset_reopens_it() -> None:
    mapper = Mapper(GamepadConfig(gripper_open=0.8, gripper_close=-0.6))
    x = PadState(held=frozenset({"gripper"}))
    grip = [float(c.action[3]) for c in step(mapper, x, x, x, PadState(), x, PadState(), x)]
    assert grip == pytest.approx([-0.6, -0.6, -0.6, -0.6, 0.8, 0.8, -0.6])
    mapper.reset()
    assert mapper(PadState()).action[3] == pytest.approx(0.8)


@pytest.mark.parametrize("role, event", [("discard", "discard"), ("quit", "quit"), ("finish", "finish"),
                                         ("camera", "switch_camera")])
def test_event_buttons_fire_on_the_press_edge_only(role: str, event: str) -> None:
    down = PadState(held=frozenset({role}))
    fired = [getattr(c, event) for c in step(Mapper(GamepadConfig()), PadState(), down, down, PadState(), down)]
    assert fired == [False, True, False, False, True]


def test_resync_ignores_buttons_already_down() -> None:
    mapper = Mapper(GamepadConfig())
    mapper.resync()
    down = PadState(held=frozenset({"quit", "gripper"}))
    first, second = step(mapper, down, down)
    assert not first.quit and not second.quit and first.action[3] == 1.0


def test_controller_triggers_are_zero_to_one() -> None:
    (c,) = step(Mapper(GamepadConfig()), PadState(lt=0.25, rt=0.75))
    assert c.action[2] == pytest.approx(0.5)


def test_raw_triggers_untouched_zero_reads_released_and_full_range_is_linear() -> None:
    raw = GamepadConfig(axis_lt=2, axis_rt=5)
    mapper = Mapper(raw)
    # many drivers report 0 until the first touch: that is "released", not half pressed
    rt = [float(mapper(PadState(lt=-1.0, rt=v)).action[2]) for v in (0.0, -1.0, -0.02, 0.0, 0.02, 0.5, 1.0)]
    assert rt == pytest.approx([0.0, 0.0, 0.49, 0.5, 0.51, 0.75, 1.0])  # the seed jumped from 0.49 to 0.02
    explicit = Mapper(dataclasses.replace(raw, trigger_range="-1..1"))
    assert [float(explicit(PadState(lt=-1.0, rt=v)).action[2]) for v in (0.0, 1.0, 0.0)] == [0.0, 1.0, 0.5]
    unit = Mapper(dataclasses.replace(raw, trigger_range="0..1"))
    assert float(unit(PadState(lt=0.0, rt=0.5)).action[2]) == pytest.approx(0.5)
    auto_unit = Mapper(raw)  # a 0..1 trigger in auto mode: small noise below 0 does not flip it
    assert [float(auto_unit(PadState(lt=0.0, rt=v)).action[2]) for v in (-0.01, 0.0, 0.5)] == \
        pytest.approx([0.0, 0.0, 0.5])


# ---- config and profiles ----


@pytest.mark.parametrize("kwargs, words", [
    ({"deadzone": 1.0}, "deadzone"), ({"pos_scale": 0.0}, "pos_scale"), ({"precision_scale": 0}, "precision"),
    ({"gripper_open": 2.0}, "gripper_open"), ({"button_x": "xx"}, "rightshoulder"), ({"axis_lx": -1}, "axis_lx"),
    ({"axis_lx": "x"}, "leftx"), ({"button_y": True}, "button_y"), ({"trigger_range": "0-1"}, "-1..1"),
    ({"deadzone": float("nan")}, "deadzone"),
])
def test_config_rejects_bad_values_naming_them(kwargs: dict[str, object], words: str) -> None:
    with pytest.raises(FetchError, match=words.replace(".", r"\.")):
        GamepadConfig(**kwargs)  # type: ignore[arg-type]


def test_profile_round_trip(tmp_path: Path) -> None:
    config = GamepadConfig(deadzone=0.2, invert_y=False, precision_scale=0.5, trigger_range="-1..1", axis_lx=3,
                           axis_lt="righty", button_x="a", button_start=9, button_camera="back", button_finish=12)
    path = tmp_path / "pad.json"
    config.save_profile(path, pad="My Pad")
    data = json.loads(path.read_text())
    assert data["axes"]["ly"] == "lefty" and data["buttons"]["precision"] == "rightshoulder"  # defaults explicit
    loaded = GamepadConfig.from_profile(path)
    assert loaded.bindings() == config.bindings()
    assert (loaded.deadzone, loaded.invert_y, loaded.precision_scale, loaded.trigger_range) == (0.2, False, 0.5,
                                                                                                "-1..1")


@pytest.mark.parametrize("text, words", [
    ("{not json", "not valid JSON"),
    ("[1, 2]", "must hold a JSON object"),
    ('{"dedzone": 0.1}', "unknown keys \\['dedzone'\\]"),
    ('{"buttons": {"grip": 2}}', "unknown buttons \\['grip'\\]; valid:"),
    ('{"buttons": {"gripper": "xbox"}}', "unknown button_x name 'xbox'"),
    ('{"axes": [0, 1]}', "\"axes\" must be an object"),
    ('{"axes": {"lx": -2}}', "axis_lx must be a raw index >= 0"),
    ('{"deadzone": "big"}', "deadzone must be a finite number"),
    ('{"format": "something else"}', "is not a version 1"),
])
def test_malformed_profile_names_the_file_and_the_problem(tmp_path: Path, text: str, words: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(FetchError, match=words) as e:
        GamepadConfig.from_profile(path)
    assert str(path) in str(e.value)


def test_missing_profile_is_a_fetch_error(tmp_path: Path) -> None:
    with pytest.raises(FetchError, match="cannot read the gamepad profile .*nope.json"):
        GamepadConfig.from_profile(tmp_path / "nope.json")


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    gamepad_command.add_parser(parser.add_subparsers())
    return parser.parse_args(["gamepad", *argv])


def _flags(*argv: str) -> PadFlags:
    """The pad's flags as `gym-fetch gamepad` parses them."""
    flags: PadFlags = options_of(PadFlags, _args(*argv))
    return flags


def test_flags_override_the_profile_but_defaults_do_not(tmp_path: Path) -> None:
    path = tmp_path / "pad.json"
    GamepadConfig(deadzone=0.3, invert_y=False, button_x=5, axis_ly=4).save_profile(path)
    config = config_from_flags(_flags("--profile", str(path), "--button-x", "7", "--pos-scale", "0.5"))
    assert (config.deadzone, config.invert_y, config.pos_scale) == (0.3, False, 0.5)
    assert (config.button_x, config.axis_ly) == (7, 4)
    seed = config_from_flags(_flags("--axis-lt", "2", "--no-invert-y"))
    assert seed.axis("lt") == 2 and seed.axis("rt") == "righttrigger" and seed.invert_y is False


# ---- the real device on a virtual SDL game controller ----


@pytest.fixture
def no_pad(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    vpad.init_headless()
    yield
    pygame.quit()


def test_no_pad_is_an_error_naming_the_other_devices(no_pad: None) -> None:
    with pytest.raises(FetchError, match="no gamepad found") as e:
        GamepadDevice()
    for device in ("keyboard", "expert", "scripted"):
        assert f"--device {device}" in str(e.value)
    assert "gym-fetch gamepad" not in str(e.value)  # the live view helps with a pad, not without one


def test_opening_a_pad_leaves_the_process_environment_as_it_was(pad: vpad.VirtualPad) -> None:
    """SDL's hints (background pad events, no prompt) are set only while SDL starts."""
    before = dict(os.environ)
    device = GamepadDevice()
    try:
        assert dict(os.environ) == before
        device.poll({})
    finally:
        device.close()
    assert dict(os.environ) == before


def test_stick_and_triggers_drive_the_action(pad: vpad.VirtualPad) -> None:
    device = GamepadDevice()
    try:
        assert device.pad.controller is not None  # read through the SDL GameController API
        np.testing.assert_allclose(device.poll({}).action, [0, 0, 0, 1])
        pad.set_stick(1.0, 0.0)
        np.testing.assert_allclose(device.poll({}).action, [1, 0, 0, 1], atol=1e-4)
        pad.set_stick(0.0, -1.0)  # up
        pad.set_triggers(0.0, 1.0)
        np.testing.assert_allclose(device.poll({}).action, [0, 1, 1, 1], atol=1e-4)
        pad.set_stick(0.0, 0.0)
        pad.set_triggers(1.0, 0.5)
        np.testing.assert_allclose(device.poll({}).action, [0, 0, -0.5, 1], atol=1e-3)
    finally:
        device.close()


def test_yaw_callable_is_read_every_poll(pad: vpad.VirtualPad) -> None:
    yaws = iter([0.0, math.pi / 2])
    device = GamepadDevice(yaw=lambda: next(yaws))
    try:
        pad.set_stick(0.0, -1.0)
        np.testing.assert_allclose(device.poll({}).action[:2], [0, 1], atol=1e-4)
        np.testing.assert_allclose(device.poll({}).action[:2], [-1, 0], atol=1e-4)
    finally:
        device.close()


def test_buttons_toggle_the_gripper_discard_quit_and_precision(pad: vpad.VirtualPad) -> None:
    device = GamepadDevice()
    try:
        device.poll({})
        pad.press("x")
        assert device.poll({}).action[3] == -1.0
        assert device.poll({}).action[3] == -1.0  # held: no second toggle
        pad.release("x")
        device.poll({})
        device.reset()
        assert device.poll({}).action[3] == 1.0
        pad.press("y")
        assert device.poll({}).discard
        assert not device.poll({}).discard
        pad.press("rightshoulder")
        pad.set_stick(1.0, 0.0)
        command = device.poll({})
        assert command.precision and command.action[0] == pytest.approx(0.3, abs=1e-4)
        pad.press("leftshoulder")
        pad.press("b")
        command = device.poll({})
        assert command.switch_camera and command.finish and not command.quit
        pad.press("start")
        assert device.poll({}).quit
    finally:
        device.close()


def test_unplugged_pad_pauses_and_resumes_when_back(pad: vpad.VirtualPad) -> None:
    device = GamepadDevice()
    try:
        device.poll({})
        pad.press("x")
        device.poll({})  # gripper closed
        pad.detach()
        for _ in range(3):
            command = device.poll({})
            assert command.paused and command.status == DISCONNECTED
            np.testing.assert_array_equal(command.action, np.zeros(4, np.float32))
        pad.attach()
        pad.press("start")  # already down when the pad comes back: fires nothing
        pad.set_stick(1.0, 0.0)
        command = device.poll({})
        assert not command.paused and not command.quit
        np.testing.assert_allclose(command.action, [1, 0, 0, -1], atol=1e-4)  # the gripper stayed closed
        pad.release("start")
        device.poll({})
        pad.press("start")
        assert device.poll({}).quit
    finally:
        device.close()


def test_unplug_is_noticed_when_a_window_takes_every_event(pad: vpad.VirtualPad) -> None:
    device = GamepadDevice()
    try:
        pad.set_stick(1.0, 0.0)
        pygame.event.get()  # the viewer reads all events each tick
        assert device.poll({}).action[0] == pytest.approx(1.0, abs=1e-4)
        pad.detach()
        pygame.event.get()
        assert device.poll({}).paused
        pad.attach()
        pygame.event.get()
        assert not device.poll({}).paused
    finally:
        device.close()


def test_raw_index_overrides_read_the_joystick_like_the_seed(pad: vpad.VirtualPad) -> None:
    raw = GamepadConfig(axis_lx=0, axis_ly=1, axis_lt=4, axis_rt=5, button_x=2, button_y=3, button_start=6)
    pad.set_axis("lefttrigger", 0.0)  # as many drivers report a trigger before its first touch
    device = GamepadDevice(raw)
    try:
        np.testing.assert_allclose(device.poll({}).action, [0, 0, 0, 1], atol=1e-4)
        pad.set_triggers(0.0, 1.0)
        np.testing.assert_allclose(device.poll({}).action, [0, 0, 1, 1], atol=1e-4)
        pad.set_triggers(0.5, 1.0)  # LT raw 0 now means half pressed
        np.testing.assert_allclose(device.poll({}).action, [0, 0, 0.5, 1], atol=1e-3)
        pad.press(2)
        assert device.poll({}).action[3] == -1.0
    finally:
        device.close()


def test_raw_index_beyond_the_pad_is_an_error(pad: vpad.VirtualPad) -> None:
    with pytest.raises(FetchError, match="raw button 20 .* has 15 buttons"):
        GamepadDevice(GamepadConfig(button_start=20))


def test_live_view_prints_what_the_pad_sends(pad: vpad.VirtualPad, capsys: pytest.CaptureFixture[str]) -> None:
    pad.set_stick(1.0, 0.0)
    start = time.monotonic()
    assert gamepad_command.run(_args("--seconds", "0.3")) == 0
    assert time.monotonic() - start < 5
    out = capsys.readouterr().out
    assert "Virtual Controller (SDL game controller)" in out
    assert "action [+1.00 +0.00 +0.00 +1.00]" in out and "leftx +1.00" in out


def test_live_view_stops_on_start(pad: vpad.VirtualPad, capsys: pytest.CaptureFixture[str]) -> None:
    def press_start() -> None:
        time.sleep(0.3)
        pad.press("start")

    presser = threading.Thread(target=press_start)
    presser.start()
    start = time.monotonic()
    assert gamepad_command.run(_args("--seconds", "20")) == 0
    presser.join()
    assert time.monotonic() - start < 10
    assert "quit" in capsys.readouterr().out


def test_calibration_finds_each_raw_index_and_the_profile_drives_the_pad(pad: vpad.VirtualPad,
                                                                         tmp_path: Path) -> None:
    pad.set_axis("lefttrigger", 0.0)  # triggers that report 0 until touched
    pad.set_axis("righttrigger", 0.0)
    actions = {"lx": lambda: pad.set_stick(1.0, 0.0), "ly": lambda: pad.set_stick(0.0, -1.0),
               "lt": lambda: pad.set_axis("lefttrigger", 1.0), "rt": lambda: pad.set_axis("righttrigger", 1.0),
               "gripper": lambda: pad.press("a"), "discard": lambda: pad.press("y"),
               "quit": lambda: pad.press("back"), "precision": lambda: pad.press("rightshoulder"),
               "camera": lambda: pad.press("leftshoulder"), "finish": lambda: pad.press("b"),
               "rewind": lambda: pad.press("rightstick")}

    def release() -> None:
        pad.set_stick(0.0, 0.0)
        pad.set_triggers(0.0, 0.0)
        for name in vpad.BUTTONS:
            pad.release(name)

    asked = []

    def say(role: str, text: str) -> None:
        asked.append(role)
        (release if role == "release" else actions.get(role, lambda: None))()

    raw = _Pad(GamepadConfig(), any_pad=True)
    try:
        config = calibrate(raw, GamepadConfig(deadzone=0.2), say, timeout=5.0)
    finally:
        raw.close()
    assert [r for r in asked if r not in ("rest", "release")] == list(actions)
    assert config.bindings() == {"lx": 0, "ly": 1, "lt": 4, "rt": 5, "gripper": 0, "discard": 3, "quit": 4,
                                 "precision": 10, "camera": 9, "finish": 1, "rewind": 8}
    assert config.invert_y is True and config.trigger_range == "-1..1" and config.deadzone == 0.2
    path = tmp_path / "pad.json"
    config.save_profile(path)
    device = GamepadDevice(GamepadConfig.from_profile(path))
    try:
        device.poll({})
        pad.set_stick(0.0, -1.0)
        pad.set_triggers(0.0, 1.0)
        pad.press("a")
        np.testing.assert_allclose(device.poll({}).action, [0, 1, 1, -1], atol=1e-4)
        pad.press("back")
        assert device.poll({}).quit
    finally:
        device.close()
