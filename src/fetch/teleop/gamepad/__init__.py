"""The gamepad device: an Xbox (or any SDL game controller) pad drives the hand.

One concept per module: `config` (layout, bindings, profiles, flags), `mapping` (pad snapshot to
command, pure), `backend` (pygame/SDL, the `Device` and its `KIND`), `tool` (`gym-fetch gamepad`).
Importing this package imports no pygame: the backend does when a pad is opened.
"""

from fetch.teleop.gamepad.backend import DISCONNECTED, KIND, GamepadDevice, RawReading, _Pad, gamepad_from_flags
from fetch.teleop.gamepad.config import (
    CONTROLS,
    STICK_AXES,
    GamepadConfig,
    PadFlags,
    add_gamepad_arguments,
    config_from_flags,
    legend,
)
from fetch.teleop.gamepad.mapping import Mapper, PadState, radial_deadzone
from fetch.teleop.gamepad.tool import PadToolRequest, calibrate, describe, run_gamepad_tool

__all__ = [
    "CONTROLS", "DISCONNECTED", "KIND", "STICK_AXES", "GamepadConfig", "GamepadDevice", "Mapper", "PadFlags",
    "PadState", "PadToolRequest", "RawReading", "_Pad", "add_gamepad_arguments", "calibrate", "config_from_flags",
    "describe", "gamepad_from_flags", "legend", "radial_deadzone", "run_gamepad_tool",
]
