"""A collection session's settings, and the one place their defaults are decided.

`gym-fetch collect` and Python callers build the same `CollectConfig`: what it leaves open (None) is
decided in `decided`, from the dataset already in `--out` (so any device adds to it without restating
how it was recorded) or else from the device's way of recording.
"""

from __future__ import annotations

import dataclasses
import pathlib
from typing import Any, cast

from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.dataset.formats import check_format
from fetch.errors import FetchError, UnknownNameError
from fetch.generate.room import STARTS
from fetch.rendering import DEFAULT_IMAGE_QUALITY, check_camera_list, check_image_quality, check_image_size
from fetch.tasks import ENV_IDS, MAX_STEPS, registered_horizon
from fetch.teleop.registry import device_kind

PERSON_MAX_STEPS = 500
"""[steps] the default length of an attempt that ends at success (a person's: 20 s at 25 Hz)."""

RENDER_CHOICES = ("auto", "human", "rgb_array", "none")


MIN_HZ, MAX_HZ = 0.1, 10_000.0
"""[Hz] the paced control rates `--control-hz` takes (0: unpaced); a person drives at 25."""
MAX_SEED = 2**62
"""The largest --seed: seed + attempt number must fit the 64-bit integer a demo stores."""


@dataclasses.dataclass(frozen=True)
class CollectConfig:
    """A collection session's settings (the `gym-fetch collect` flags)."""

    env_id: str
    out: str = "demos"
    episodes: int = 0
    """Demos to save in this session; 0: until quit."""
    max_steps: int | None = None
    """Steps per attempt; replaces the env's 50-step TimeLimit. None: decided (`decided`)."""
    seed: int = 0
    """Attempt k of the dataset resets with seed + k (with `starts` "tight": the (k+1)-th seed from `seed` on
    whose start is tight)."""
    starts: str = "all"
    """`STARTS`: "tight" makes attempts only from the starts where the object stands close beside something along
    the fingers' axis (a bin's wall: `fetch.generate.room.tight_start`), as `generate --starts tight` does: where a
    policy trained from ordinary starts is weakest, which a correction round should visit."""
    control_hz: float | None = None
    """[Hz] None: the env's real-time rate (25) for a person, as fast as possible for expert/scripted."""
    success_hold_steps: int = 10
    stop_on_success: bool | None = None
    """End an attempt once success has held `success_hold_steps`. None: decided (`decided`)."""
    ignore_env_done: bool = False
    """Keep going after `terminated` (never after the --max-steps truncation)."""
    keep_failures: bool = False
    device: str = "gamepad"
    render: str = "auto"
    format: str = "hdf5"
    reward_type: str = "sparse"
    cameras: tuple[str, ...] = ()
    image_size: int = DEFAULT_IMAGE_SIZE
    image_quality: str = DEFAULT_IMAGE_QUALITY
    """how `cameras`' images are drawn (`rendering.IMAGE_QUALITIES`)."""
    verbose: bool = False

    def __post_init__(self) -> None:
        if self.env_id not in ENV_IDS:
            raise UnknownNameError("env", self.env_id, ENV_IDS)
        object.__setattr__(self, "device", device_kind(self.device).name)  # an alias ("xbox") by its name
        if not str(self.out).strip():
            raise FetchError("--out must name a directory (it is empty); e.g. --out demos/my_task")
        stop, max_steps = decided(self.env_id, self.device, self.out, self.stop_on_success, self.max_steps)
        object.__setattr__(self, "stop_on_success", stop)
        object.__setattr__(self, "max_steps", max_steps)
        check_format(self.format, self.cameras)
        if self.starts not in STARTS:
            raise UnknownNameError("starts", self.starts, STARTS)
        if self.render not in RENDER_CHOICES:
            raise UnknownNameError("render mode", self.render, RENDER_CHOICES)
        for name, value, low in (("--episodes", self.episodes, 0), ("--max-steps", max_steps, 1),
                                 ("--success-hold-steps", self.success_hold_steps, 1)):
            if value < low:
                raise FetchError(f"{name} must be at least {low}, got {value}")
        if max_steps > MAX_STEPS:
            raise FetchError(f"--max-steps must be at most {MAX_STEPS} (over an hour at 25 Hz), got {max_steps}")
        check_image_size(self.image_size, "--image-size")
        check_image_quality(self.image_quality, "--image-quality")
        check_camera_list(self.cameras)
        if not 0 <= self.seed <= MAX_SEED:
            raise FetchError(f"--seed must be a whole number from 0 to 2**62 (every demo stores its reset seed as a "
                             f"64-bit integer), got {self.seed}")
        if self.control_hz is not None and not (self.control_hz == 0 or MIN_HZ <= self.control_hz <= MAX_HZ):
            raise FetchError(f"--control-hz must be 0 (as fast as possible) or a rate from {MIN_HZ:g} to "
                             f"{MAX_HZ:g} Hz, got {self.control_hz}")

    @property
    def attempt_steps(self) -> int:
        """[steps] the longest attempt: `max_steps` as decided (never None once built)."""
        return cast(int, self.max_steps)

    @property
    def human(self) -> bool:
        """A person drives the device: real-time pacing, and a window when there is a display."""
        return device_kind(self.device).human

    def rate(self, env_dt: float) -> float:
        """[Hz] the control rate to keep; 0 means as fast as possible."""
        if self.control_hz is not None:
            return self.control_hz
        return 1.0 / env_dt if self.human or self.render == "human" else 0.0

    def settings(self) -> dict[str, Any]:
        """What a resumed session must match."""
        settings = {"max_steps": self.max_steps, "success_hold_steps": self.success_hold_steps,
                    "stop_on_success": self.stop_on_success, "ignore_env_done": self.ignore_env_done}
        return settings | ({"starts": self.starts} if self.starts != "all" else {})  # datasets before it match


def decided(env_id: str, device: str, out: str, stop_on_success: bool | None,
            max_steps: int | None) -> tuple[bool, int]:
    """(stop_on_success, max_steps) with what is None filled in: from the settings the dataset in `out`
    was recorded with, else from the device: an attempt ends at success within `PERSON_MAX_STEPS`, or,
    for a device that `holds_past_success` (the expert, recording to the horizon), runs to the task's
    registered horizon."""
    recorded = recorded_settings(out) if stop_on_success is None or max_steps is None else {}
    if stop_on_success is None:
        stop_on_success = bool(recorded.get("stop_on_success", not device_kind(device).holds_past_success))
    if max_steps is None:
        max_steps = recorded.get("max_steps")
    if max_steps is None:
        max_steps = PERSON_MAX_STEPS if stop_on_success else registered_horizon(env_id)
    return stop_on_success, int(max_steps)


def recorded_settings(out: str) -> dict[str, Any]:
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
