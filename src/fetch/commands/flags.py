"""The flags `gym-fetch collect` and `gym-fetch generate` share, declared once; where the two commands give
one a different default or meaning, `COLLECT` and `GENERATE` say so side by side: --out (collect: default
demos; generate: required), --max-steps (each leaves it to its library), --success-hold-steps (10 and 5),
--stop-on-success (collect: decided per device and dataset; generate: off), --cameras (the same list,
rendered live or in the workers)."""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any

from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.rendering import CAMERAS, DEFAULT_IMAGE_QUALITY, IMAGE_QUALITIES, QUALITY_HELP


@dataclasses.dataclass(frozen=True)
class Recording:
    """One recording command's defaults and help for the shared flags, where they differ between commands."""

    out_help: str
    out_default: str | None
    """None: --out is required."""
    max_steps_help: str
    success_hold_steps: int
    success_hold_help: str
    stop_on_success: bool | None
    """None: decided by the library (`fetch.teleop.config.decided`)."""
    stop_on_success_help: str
    cameras_help: str


COLLECT = Recording(
    out_help="output directory (default demos; resumed if it holds a matching dataset)",
    out_default="demos",
    max_steps_help="steps per attempt at most (default 500, replacing the 50-step training limit; for the expert "
                   "the task's horizon, 50)",
    success_hold_steps=10,
    success_hold_help="steps success must hold before the attempt ends (default 10)",
    stop_on_success=None,
    stop_on_success_help="end the attempt once success has held (default on; off for the expert, whose demos run "
                         "to the task's horizon)",
    cameras_help=f"record these cameras' images too, comma-separated ({', '.join(CAMERAS)}); default none",
)
"""`gym-fetch collect`'s."""

GENERATE = Recording(
    out_help="the output directory (a dataset like collect's)",
    out_default=None,
    max_steps_help="steps per attempt (default: the env's horizon, or more where the source demos, their idle "
                   "steps left out, need it)",
    success_hold_steps=5,
    success_hold_help="success must hold over an attempt's last this many steps (default 5)",
    stop_on_success=False,
    stop_on_success_help="end an attempt once success has held --success-hold-steps (MimicGen's demos end there; "
                         "default off: every attempt runs to --max-steps, the last segment to its source's end and "
                         "then holding still, so a policy learns to stay done)",
    cameras_help=f"record these cameras' images too, comma-separated ({', '.join(CAMERAS)}), rendered from "
                 "each demo's states in the workers as collect --cameras records them; default none",
)
"""`gym-fetch generate`'s."""


def add_out(p: argparse.ArgumentParser, r: Recording) -> None:
    if r.out_default is None:
        p.add_argument("--out", required=True, help=r.out_help)
    else:
        p.add_argument("--out", default=r.out_default, help=r.out_help)


def add_seed(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, default=0,
                   help="attempt k of the dataset resets with seed + k (default 0; a whole number >= 0)")


def add_max_steps(p: argparse.ArgumentParser, r: Recording) -> None:
    p.add_argument("--max-steps", type=int, default=None, help=r.max_steps_help)


def add_success(p: argparse.ArgumentParser, r: Recording) -> None:
    """--success-hold-steps and --stop-on-success."""
    p.add_argument("--success-hold-steps", type=int, default=r.success_hold_steps, help=r.success_hold_help)
    p.add_argument("--stop-on-success", action=argparse.BooleanOptionalAction, default=r.stop_on_success,
                   help=r.stop_on_success_help)


def add_images(p: argparse.ArgumentParser, r: Recording) -> None:
    """--cameras, --image-size and --image-quality: the cameras' images recorded beside the state."""
    p.add_argument("--cameras", default="", help=r.cameras_help)
    p.add_argument("--image-size", type=int, default=DEFAULT_IMAGE_SIZE,
                   help=f"recorded image width and height [px] (default {DEFAULT_IMAGE_SIZE})")
    p.add_argument("--image-quality", default=DEFAULT_IMAGE_QUALITY, choices=IMAGE_QUALITIES, help=QUALITY_HELP)


def camera_list(text: str | None) -> tuple[str, ...]:
    """A comma-separated list of camera names as a tuple (blanks dropped; None or "": none)."""
    return tuple(c.strip() for c in text.split(",") if c.strip()) if text else ()


def options_of(options: type[Any], args: argparse.Namespace) -> Any:
    """An options dataclass (a `DeviceKind.options`, `PadFlags`) of the flags parsed into `args`: each field from
    the flag of that destination (a field with no flag here keeps its default)."""
    return options(**{f.name: getattr(args, f.name) for f in dataclasses.fields(options) if hasattr(args, f.name)})


def request_of(request: type[Any], args: argparse.Namespace) -> Any:
    """A request dataclass (`TrainRequest`, `ExportRequest`, `ReplayRequest`) of the flags parsed into `args`, every
    field from the flag of that destination: a field with no flag is an AttributeError, not a silent default."""
    return request(**{f.name: getattr(args, f.name) for f in dataclasses.fields(request)})
