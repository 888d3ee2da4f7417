"""From command-line arguments to a collection session: config (whose defaults `teleop.config` decides),
env, device, window."""

from __future__ import annotations

import argparse
import sys

from fetch._gl import has_display
from fetch.errors import FetchError
from fetch.teleop.devices import Device, DeviceContext
from fetch.teleop.registry import device_kind
from fetch.teleop.session import CollectConfig, Display, Session, make_env


def config_from_args(args: argparse.Namespace) -> CollectConfig:
    cameras = tuple(c.strip() for c in args.cameras.split(",") if c.strip()) if args.cameras else ()
    return CollectConfig(
        env_id=args.env, out=args.out, episodes=args.episodes, max_steps=args.max_steps, seed=args.seed,
        control_hz=args.control_hz, success_hold_steps=args.success_hold_steps,
        stop_on_success=args.stop_on_success, ignore_env_done=args.ignore_env_done,
        keep_failures=args.keep_failures, device=args.device, render=args.render, format=args.format,
        reward_type=args.reward_type, cameras=cameras, image_size=args.image_size,
        image_quality=args.image_quality, verbose=args.verbose)


def wants_window(config: CollectConfig) -> bool:
    if config.render == "human":
        return True
    return config.render == "auto" and has_display() and config.human


NO_WINDOW = ("{what} reads keys typed into the collection window, and there is no display to open it on. What works: "
             "a desktop session (or ssh -X); a virtual display, for keys sent by a program (xvfb-run -a gym-fetch "
             "collect ...); or a device that needs no window: --device expert (the task's scripted expert), "
             "--device scripted (events from --scripted-json) or --device gamepad (a pad; --render none)")


def check_window(config: CollectConfig, args: argparse.Namespace) -> None:
    """FetchError, before anything opens, when what a person drives with reads the window (the keyboard) and
    no window will open: one message saying what works."""
    from fetch.teleop.viewer import window_possible

    kind = device_kind(config.device)
    flag = f"--device {kind.name}"
    if kind.legend_from:  # a person drives through another device (takeover): that one may read the window
        through = kind.legend_from
        kind = device_kind(getattr(args, through))
        flag = f"--{through.replace('_', '-')} {kind.name}"
    if not kind.reads_window:
        return
    if not window_possible():
        raise FetchError(NO_WINDOW.format(what=flag))
    if not wants_window(config):
        raise FetchError(f"{flag} reads keys typed into the collection window, which --render {config.render} does "
                         "not open: leave --render out (auto opens it on a display) or use --render human")


def make_device(config: CollectConfig, args: argparse.Namespace, env: object, viewer: Display | None) -> Device:
    yaw = getattr(viewer, "yaw", None) if getattr(args, "frame", "camera") == "camera" else None
    return device_kind(config.device).build(DeviceContext(env=env, args=args, viewer=viewer, yaw=yaw))


def session_from_args(args: argparse.Namespace) -> Session:
    config = config_from_args(args)
    # The devices read the flags: give them what the config decided for those left unset.
    args = argparse.Namespace(**{**vars(args), "stop_on_success": config.stop_on_success,
                                 "max_steps": config.max_steps})
    check_window(config, args)
    env = make_env(config)
    viewer: Display | None = None
    if wants_window(config):
        from fetch.teleop.viewer import Viewer

        kind = device_kind(config.device)
        legend = kind.legend + (device_kind(getattr(args, kind.legend_from)).legend if kind.legend_from else ())
        viewer = Viewer(env, legend)
    try:
        device = make_device(config, args, env, viewer)
    except BaseException:
        if viewer is not None:
            viewer.close()
        raise
    print(f"collecting {config.env_id} with {config.device} into {config.out} "
          f"({'until you quit' if not config.episodes else f'{config.episodes} demos'})", file=sys.stderr)
    return Session(config, device, env=env, display=viewer)
