"""From command-line arguments to a collection session: config (whose defaults `teleop.config` decides),
env, device, window."""

from __future__ import annotations

import argparse
import sys

from fetch._gl import has_display
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


def make_device(config: CollectConfig, args: argparse.Namespace, env: object, viewer: Display | None) -> Device:
    yaw = getattr(viewer, "yaw", None) if getattr(args, "frame", "camera") == "camera" else None
    return device_kind(config.device).build(DeviceContext(env=env, args=args, viewer=viewer, yaw=yaw))


def session_from_args(args: argparse.Namespace) -> Session:
    config = config_from_args(args)
    # The devices read the flags: give them what the config decided for those left unset.
    args = argparse.Namespace(**{**vars(args), "stop_on_success": config.stop_on_success,
                                 "max_steps": config.max_steps})
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
