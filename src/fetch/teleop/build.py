"""From command-line arguments to a collection session: config, env, device, window."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from fetch.errors import FetchError
from fetch.teleop.devices import (
    Device,
    ExpertDevice,
    ScriptedDevice,
    builtin_notice,
    default_script,
    load_script,
)
from fetch.teleop.session import CollectConfig, Display, Session, make_env


def config_from_args(args: argparse.Namespace) -> CollectConfig:
    cameras = tuple(c.strip() for c in args.cameras.split(",") if c.strip()) if args.cameras else ()
    return CollectConfig(
        env_id=args.env, out=args.out, episodes=args.episodes, max_steps=args.max_steps, seed=args.seed,
        control_hz=args.control_hz, success_hold_steps=args.success_hold_steps,
        stop_on_success=args.stop_on_success, ignore_env_done=args.ignore_env_done,
        keep_failures=args.keep_failures, device="gamepad" if args.device == "xbox" else args.device,
        render=args.render, format=args.format, reward_type=args.reward_type, cameras=cameras,
        image_size=args.image_size, verbose=args.verbose)


def wants_window(config: CollectConfig) -> bool:
    if config.render == "human":
        return True
    return config.render == "auto" and bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) \
        and config.human


def make_device(config: CollectConfig, args: argparse.Namespace, env: Any, viewer: Any) -> Device:
    if config.device == "expert":
        return ExpertDevice(env)
    if config.device == "scripted":
        if args.scripted_json:
            events = load_script(args.scripted_json)
            print(f"scripted: {len(events)} events from {args.scripted_json}, one per control tick; the list runs "
                  "on across attempts and the session quits when it runs out", file=sys.stderr)
        else:
            events = default_script()
            print(builtin_notice(config.keep_failures, config.max_steps), file=sys.stderr)
        return ScriptedDevice(events, log=lambda text: print(text, flush=True))
    yaw = viewer.yaw if viewer is not None and getattr(args, "frame", "camera") == "camera" else None
    if config.device == "keyboard":
        if viewer is None:
            raise FetchError("--device keyboard reads keys in the viewer window; use --render human "
                             "(or auto, with a display)")
        from fetch.teleop.keyboard import KeyboardDevice

        return KeyboardDevice(viewer, yaw)
    from fetch.teleop.gamepad import gamepad_from_args

    return gamepad_from_args(args, yaw=yaw)


def session_from_args(args: argparse.Namespace) -> Session:
    config = config_from_args(args)
    env = make_env(config)
    viewer: Display | None = None
    if wants_window(config):
        from fetch.teleop.viewer import Viewer

        viewer = Viewer(env, config.device)
    try:
        device = make_device(config, args, env, viewer)
    except BaseException:
        if viewer is not None:
            viewer.close()
        raise
    print(f"collecting {config.env_id} with {config.device} into {config.out} "
          f"({'until you quit' if not config.episodes else f'{config.episodes} demos'})", file=sys.stderr)
    return Session(config, device, env=env, display=viewer)
