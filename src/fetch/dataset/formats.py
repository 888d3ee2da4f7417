"""The formats a collector records in, chosen here behind one interface (`BackgroundWriter`):
hdf5 (robomimic's layout, crash-safe, replayable) and npz (one file per demo, collect_fetch_demo.py's format)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from fetch.dataset import schema
from fetch.dataset.background import BackgroundWriter
from fetch.dataset.episode import Demo
from fetch.errors import FetchError, UnknownNameError
from fetch.rendering import DEFAULT_IMAGE_QUALITY

FORMATS = ("hdf5", "npz")
"""`collect --format` choices; the first is the default."""


def check_format(format: str, cameras: tuple[str, ...] = ()) -> None:
    if format not in FORMATS:
        raise UnknownNameError("format", format, FORMATS)
    if cameras and format != "hdf5":
        raise FetchError("--cameras needs --format hdf5 (the npz files hold no images)")


def recorded_layout(env: gym.Env, cameras: tuple[str, ...] = (), image_size: int = 0,
                    image_quality: str = DEFAULT_IMAGE_QUALITY) -> schema.Layout:
    """What a demo of `env` holds: its observation keys' sizes, its state size, the cameras' images (of
    `image_size` [px], drawn at `image_quality`)."""
    space = env.observation_space
    sizes = tuple((key, int(space[key].shape[0])) for key in schema.OBS_KEYS)  # type: ignore[index]
    return schema.Layout(obs_sizes=sizes, state_size=env.unwrapped.state_size,  # type: ignore[attr-defined]
                         cameras=cameras, image_size=image_size if cameras else 0,
                         image_quality=image_quality if cameras else "full")


def open_writer(format: str, out: str, env: gym.Env, *, settings: dict[str, Any], device: str,
                cameras: tuple[str, ...] = (), image_size: int = 0, image_quality: str = DEFAULT_IMAGE_QUALITY,
                on_saved: Callable[[str, Demo], None] | None = None) -> BackgroundWriter:
    """The writer of `format` for the directory `out`: resumes what is there (if it matches) and locks it.
    `settings` are what a resumed session must match (hdf5) or are recorded (npz)."""
    check_format(format, cameras)
    base: Any = env.unwrapped
    env_id = base.spec.id if base.spec is not None else str(env)
    if format == "npz":
        from fetch.dataset.npz import NpzWriter

        metadata = {"env_id": env_id, "max_steps": settings["max_steps"], "device": device,
                    "action_space": str(env.action_space), "observation_space": str(env.observation_space),
                    "argv": sys.argv, "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        return NpzWriter(out, env_id, metadata, on_saved)
    from fetch.dataset.writer import DatasetWriter, Header, package_versions

    # What a dataset's states are rendered with later (render-obs, replay, a policy's eval) beside the reward:
    # the looks where drawn, and the goal's marker where hidden, as the env that recorded them drew its images.
    drawn = {"looks": base.looks_mode} if base.looks_mode != "plain" else {}
    hidden = {"hide_goal": True} if base.hide_goal else {}
    header = Header(env_id=env_id, env_kwargs={"reward_type": base.reward_type, **drawn, **hidden},
                    layout=recorded_layout(env, cameras, image_size, image_quality), settings=settings,
                    model_xml=base.model_xml(), model_hash=base.model_hash(), versions=package_versions(),
                    legacy_model_hash=base.legacy_model_hash())
    return DatasetWriter(out, header, on_saved)
