"""From command-line arguments to a collection session: config, env, device, window."""

from __future__ import annotations

import argparse
import pathlib
import sys
from typing import Any

from fetch._gl import has_display
from fetch.errors import FetchError
from fetch.teleop.devices import Device, DeviceContext
from fetch.teleop.registry import device_kind
from fetch.teleop.session import CollectConfig, Display, Session, make_env

MAX_STEPS = 500
"""The default --max-steps of an attempt that ends at success (a person's)."""


def with_device_defaults(args: argparse.Namespace) -> argparse.Namespace:
    """`args` with the flags left unset (None) filled in: when `--out` holds a dataset, from the
    settings it was recorded with (so any device adds to it without restating them); for a new one,
    from the device: an attempt ends at success and within `MAX_STEPS`, or, for a device that
    `holds_past_success`, runs to the task's registered horizon."""
    import gymnasium as gym

    recorded = _recorded_settings(args.out)
    stop = args.stop_on_success
    if stop is None:
        stop = recorded.get("stop_on_success", not device_kind(args.device).holds_past_success)
    max_steps = args.max_steps if args.max_steps is not None else recorded.get("max_steps")
    if max_steps is None:  # (an unknown --env is refused by CollectConfig, naming the valid ones)
        horizon = gym.spec(args.env).max_episode_steps if args.env in gym.registry else None
        max_steps = MAX_STEPS if stop or not horizon else int(horizon)
    return argparse.Namespace(**{**vars(args), "stop_on_success": stop, "max_steps": max_steps})


def _recorded_settings(out: str) -> dict[str, Any]:
    """The settings of the dataset in `out` ({} if there is none, or it cannot be read: the session
    then reports why)."""
    if not out or not pathlib.Path(out).is_dir():
        return {}
    from fetch.dataset import open_dataset

    try:
        with open_dataset(out) as ds:
            return dict(ds.settings)
    except (FetchError, OSError):
        return {}


def config_from_args(args: argparse.Namespace) -> CollectConfig:
    cameras = tuple(c.strip() for c in args.cameras.split(",") if c.strip()) if args.cameras else ()
    return CollectConfig(
        env_id=args.env, out=args.out, episodes=args.episodes, max_steps=args.max_steps, seed=args.seed,
        control_hz=args.control_hz, success_hold_steps=args.success_hold_steps,
        stop_on_success=args.stop_on_success, ignore_env_done=args.ignore_env_done,
        keep_failures=args.keep_failures, device=args.device, render=args.render, format=args.format,
        reward_type=args.reward_type, cameras=cameras, image_size=args.image_size, verbose=args.verbose)


def wants_window(config: CollectConfig) -> bool:
    if config.render == "human":
        return True
    return config.render == "auto" and has_display() and config.human


def make_device(config: CollectConfig, args: argparse.Namespace, env: object, viewer: Display | None) -> Device:
    yaw = getattr(viewer, "yaw", None) if getattr(args, "frame", "camera") == "camera" else None
    return device_kind(config.device).build(DeviceContext(env=env, args=args, viewer=viewer, yaw=yaw))


def session_from_args(args: argparse.Namespace) -> Session:
    args = with_device_defaults(args)
    config = config_from_args(args)
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
