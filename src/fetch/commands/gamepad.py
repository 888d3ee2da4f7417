"""`gym-fetch gamepad`: its flags, and the live view or calibration they ask for
(`fetch.teleop.gamepad.tool.run_gamepad_tool`, with a `PadToolRequest`)."""

from __future__ import annotations

import argparse

from fetch.commands.flags import options_of
from fetch.teleop.gamepad.config import PadFlags, add_gamepad_arguments


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """The `gamepad` subcommand: live view of the pad, or a guided calibration that writes a profile."""
    p = sub.add_parser(
        "gamepad", help="show what the pad sends (axes, buttons, the action), or calibrate it (--calibrate)")
    add_gamepad_arguments(p)
    p.add_argument("--seconds", type=float, default=0.0,
                   help="stop after this long [s] (default 0: until START or Ctrl-C)")
    p.add_argument("--calibrate", action="store_true", help="guided mapping of each control; needs --out")
    p.add_argument("--out", default=None, help="the profile file --calibrate writes (JSON)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.teleop.gamepad.tool import PadToolRequest, run_gamepad_tool

    return run_gamepad_tool(PadToolRequest(pad=options_of(PadFlags, args), seconds=args.seconds,
                                           calibrate=args.calibrate, out=args.out))
