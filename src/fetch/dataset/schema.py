"""The dataset's layout, declared once: checked on write, on read, and printed in docs/datasets.md."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from fetch.camera_obs import image_key  # the env's observation key is the dataset's
from fetch.rendering import IMAGE_QUALITIES

FORMAT = "gym-fetch-v2/demos"
FORMAT_VERSION = 1
INDEX_NAME = "demos.hdf5"
"""The dataset file inside an output directory; it links to one file per demo."""
EPISODES_DIR = "episodes"
"""Where the per-demo files live, next to the index (external links are relative to it)."""
ENV_TYPE_GYM = 2
"""robomimic's `EnvType.GYM_TYPE`, the `type` in `env_args`."""
OBS_KEYS = ("observation", "achieved_goal", "desired_goal")
SPLITS = ("train", "valid", "failed")
"""The masks that partition a dataset's demos: successful ones train or valid, kept failures failed."""


@dataclasses.dataclass(frozen=True)
class Field:
    """One array of a demo group: `path` relative to `data/demo_<i>`, rows = T + `extra_rows`."""

    path: str
    dtype: str
    tail: tuple[int, ...]
    doc: str
    extra_rows: int = 0

    def shape(self, num_samples: int) -> tuple[int, ...]:
        return (num_samples + self.extra_rows, *self.tail)


@dataclasses.dataclass(frozen=True)
class Layout:
    """What every demo of one dataset holds, given the env's sizes and the recorded cameras."""

    obs_sizes: tuple[tuple[str, int], ...]
    state_size: int
    cameras: tuple[str, ...] = ()
    image_size: int = 0
    image_quality: str = "full"
    """how the images are drawn (`rendering.IMAGE_QUALITIES`); a layout without one (recorded before there
    was a choice) holds "full" images."""

    def __post_init__(self) -> None:
        if self.cameras and self.image_size <= 0:
            raise ValueError(f"image_size must be positive pixels when cameras are recorded, got {self.image_size}")
        if self.image_quality not in IMAGE_QUALITIES:
            raise ValueError(f"image_quality must be one of {', '.join(IMAGE_QUALITIES)}, got {self.image_quality!r}")

    @property
    def obs_keys(self) -> tuple[str, ...]:
        return tuple(k for k, _ in self.obs_sizes) + tuple(image_key(c) for c in self.cameras)

    def fields(self) -> tuple[Field, ...]:
        out = [Field("actions", "float32", (4,), "the action applied at step t, each value in [-1, 1]")]
        for prefix, when in (("obs", "before"), ("next_obs", "after")):
            for key, size in self.obs_sizes:
                out.append(Field(f"{prefix}/{key}", "float64", (size,), f"`{key}` {when} step t"))
            for camera in self.cameras:
                out.append(Field(f"{prefix}/{image_key(camera)}", "uint8", (self.image_size, self.image_size, 3),
                                 f"camera `{camera}` image {when} step t"))
        out += [
            Field("rewards", "float64", (), "reward of step t"),
            Field("dones", "uint8", (), "1 at the demo's last step, else 0"),
            Field("terminated", "bool", (), "the env's `terminated` of step t"),
            Field("truncated", "bool", (), "the env's `truncated` of step t (the --max-steps limit)"),
            Field("is_success", "uint8", (), "`info['is_success']` after step t"),
            Field("states", "float64", (self.state_size,),
                  "`mj_getState` (mjSTATE_INTEGRATION, mocap included) before every step and after the last",
                  extra_rows=1),
            Field("timestamps", "float64", (), "[s] wall-clock (Unix) time at which step t was applied"),
        ]
        return tuple(out)

    def with_cameras(self, cameras: tuple[str, ...], image_size: int, image_quality: str) -> Layout:
        return dataclasses.replace(self, cameras=cameras, image_size=image_size, image_quality=image_quality)


OPTIONAL_FIELDS: tuple[Field, ...] = (
    Field("expert_actions", "float32", (4,),
          "the action the device meant at step t where it sent a perturbed one on purpose (the expert under "
          "DART noise): what a policy learns, while `actions` replays the demo"),
    Field("subtasks", "uint8", (), "`gym-fetch generate` output: the index of the task's subtask step t belongs to"),
    Field("intervention", "uint8", (),
          "`--device takeover`: 1 where the person drove step t (having taken over from the policy), 0 where the "
          "policy did"),
    Field("policy_actions", "float32", (4,),
          "`--device takeover`: the action the policy proposed at step t (where it drove, the action applied)"),
)
"""Arrays some demos hold; checked like the others when present."""


def is_image(path: str) -> bool:
    """Whether a demo's array at `path` (e.g. `obs/front_image`) is a camera's images."""
    return path.endswith(image_key(""))


def meant_actions(arrays: Mapping[str, Any]) -> np.ndarray:
    """A demo's (T, 4) actions to learn from: `expert_actions` where recorded, else `actions` (the
    device meant what it sent). Every export carries them beside the applied `actions`."""
    return np.asarray(arrays["expert_actions"] if "expert_actions" in arrays else arrays["actions"], np.float32)


DEMO_ATTRS: tuple[tuple[str, str], ...] = (
    ("num_samples", "T, the number of steps (robomimic)"),
    ("seed", "the `env.reset(seed=...)` of this episode"),
    ("success", "success held for the session's --success-hold-steps"),
    ("env_id", "the Gymnasium id"),
    ("device", "what produced the actions: gamepad, keyboard, scripted, expert"),
    ("attempt", "the attempt number within the dataset (0-based, counts discarded attempts)"),
    ("control_hz", "[Hz] target control rate (0: as fast as possible)"),
    ("achieved_hz", "[Hz] achieved control rate"),
    ("started", "[s] Unix time of the reset"),
    ("ended", "[s] Unix time of the last step"),
)

DEMO_ATTR_KINDS: dict[str, str] = {
    "num_samples": "count", "seed": "count", "attempt": "count", "success": "bool", "env_id": "text",
    "device": "text", "control_hz": "number", "achieved_hz": "number", "started": "number", "ended": "number",
}
"""What each of `DEMO_ATTRS` holds: count (a whole number from 0 to 2**63 - 1), bool, text or number
(finite)."""
DATA_ATTR_KINDS: dict[str, str] = {"total": "count", "attempts": "count", "created": "number"}
"""The kinds of the numeric `DATA_ATTRS` (the others are JSON or text, read by `reader.Dataset`)."""
_KINDS = {"count": "a whole number from 0 to 2**63 - 1", "bool": "a boolean", "text": "a string",
          "number": "a finite number"}


def kind_problem(value: Any, kind: str) -> str | None:
    """`is <value>, expected <kind>` if `value` is not of `kind` (see `DEMO_ATTR_KINDS`), else None."""
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    boolean = isinstance(value, bool | np.bool_)
    if kind == "count":  # int64 holds it: what every consumer stores a seed or a count in
        ok = isinstance(value, int | np.integer) and not boolean and 0 <= value < 2**63
    elif kind == "bool":
        ok = boolean or (isinstance(value, int | np.integer) and value in (0, 1))
    elif kind == "text":
        ok = isinstance(value, str | bytes)
    else:
        ok = isinstance(value, int | float | np.integer | np.floating) and not boolean and bool(np.isfinite(value))
    return None if ok else f"is {value!r}, expected {_KINDS[kind]}"


def check_demo_attrs(attrs: Mapping[str, Any]) -> list[str]:
    """Problems of one demo's attributes (missing ones, or of the wrong kind); empty when they conform."""
    missing = [key for key, _ in DEMO_ATTRS if key not in attrs]
    if missing:
        return [f"missing attribute(s) {', '.join(missing)}"]
    found = {key: kind_problem(attrs[key], kind) for key, kind in DEMO_ATTR_KINDS.items()}
    return [f"attribute {key} {p}" for key, p in found.items() if p is not None]


DATA_ATTRS: tuple[tuple[str, str], ...] = (
    ("total", "steps in all demos (robomimic)"),
    ("env_args", "JSON `{env_name, type, env_kwargs}` (robomimic)"),
    ("format", f"`{FORMAT}`"),
    ("format_version", f"{FORMAT_VERSION}"),
    ("versions", "JSON: fetch, mujoco, gymnasium, numpy, h5py versions that created the file"),
    ("created", "[s] Unix time the dataset was created"),
    ("settings", "JSON: the collection settings a resumed session must match"),
    ("layout", "JSON: observation sizes, state size, cameras, image size and, with cameras, image quality "
               "(`fast` or `full`; absent: `full`)"),
    ("model_xml", "the compiled MuJoCo model as MJCF"),
    ("model_hash", "SHA-256 of the compiled model (MJB, asset files by relative name, so the same on any "
                   "install); a resumed session or a merge must match it"),
    ("attempts", "attempts made so far (the next attempt's number)"),
)

TOOL_ATTRS: tuple[tuple[str, str], ...] = (
    ("data.attrs['sources']", "`merge` only: JSON list of the merged datasets (path, demos, settings, versions)"),
    ("data.attrs['split']", "after `split`: JSON `{valid, seed}` it was made with"),
    ("data/demo_<i>.attrs['source']", "`merge` only: `<dataset>:<demo>` the demo came from"),
)
"""Attributes the dataset tools add (optional: files without them are valid)."""


def layout_to_json(layout: Layout) -> str:
    raw = {"obs_sizes": [list(x) for x in layout.obs_sizes], "state_size": layout.state_size,
           "cameras": list(layout.cameras), "image_size": layout.image_size}
    if layout.cameras:  # without images the JSON is as it was before image_quality existed
        raw["image_quality"] = layout.image_quality
    return json.dumps(raw)


def layout_from_json(text: str) -> Layout:
    raw = json.loads(text)
    return Layout(obs_sizes=tuple((str(k), int(n)) for k, n in raw["obs_sizes"]), state_size=int(raw["state_size"]),
                  cameras=tuple(raw.get("cameras", ())), image_size=int(raw.get("image_size", 0)),
                  image_quality=str(raw.get("image_quality", "full")))


def demo_name(index: int) -> str:
    return f"demo_{index}"


def demo_index(name: str) -> int:
    """The integer of `demo_<i>`; ValueError for any other name."""
    prefix, _, number = name.partition("_")
    if prefix != "demo" or not number.isdigit():
        raise ValueError(f"{name!r} is not a demo name (demo_<integer>)")
    return int(number)


def check_arrays(arrays: Mapping[str, Any], layout: Layout, num_samples: int) -> list[str]:
    """Problems of one demo's arrays against the layout (empty when it conforms)."""
    problems = []
    present = tuple(f for f in OPTIONAL_FIELDS if f.path in arrays)
    for field in layout.fields() + present:
        if field.path not in arrays:
            problems.append(f"missing {field.path}")
            continue
        array = arrays[field.path]
        want = field.shape(num_samples)
        if tuple(array.shape) != want:
            problems.append(f"{field.path} has shape {tuple(array.shape)}, expected {want}")
        if np.dtype(array.dtype) != np.dtype(field.dtype):
            problems.append(f"{field.path} has dtype {array.dtype}, expected {field.dtype}")
    return problems


def episode_seed(attrs: Mapping[str, Any]) -> int | None:
    """A demo's reset seed from its attributes (what its looks are drawn from under looks="random",
    `fetch.looks`), or None where it has none that is a whole number."""
    seed = attrs.get("seed")
    return int(seed) if isinstance(seed, int | np.integer) and not isinstance(seed, bool) else None
