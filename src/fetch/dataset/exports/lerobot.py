"""The LeRobotDataset v3.0 format: its paths, features, statistics and task strings (`lerobot_writer` writes it).

The layout is LeRobot's (`lerobot.datasets.utils`, release 0.4.4): `data/chunk-000/file-000.parquet` holds
one row per frame, `videos/<key>/chunk-000/file-000.mp4` the frames of every episode one after another,
`meta/episodes/chunk-000/file-000.parquet` one row per episode (where its rows and frames are, its
statistics), `meta/tasks.parquet` the task strings, `meta/stats.json` and `meta/info.json`. A frame is
one control step: the observation before step t, the action of step t and what step t gave
(`next.reward`, `next.done`, `next.success`); the state after the last step has no frame. Images are
the dataset's own where it recorded them as asked (camera, size, quality), else rendered from the saved states.
"""

from __future__ import annotations

import collections
import math
import pathlib
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from fetch.dataset import schema
from fetch.dataset.dirs import env_dir
from fetch.errors import FetchError, install_hint

CODEBASE_VERSION = "v3.0"
INSTALL = install_hint("lerobot")
CHUNK_SIZE = 1000
"""Files per chunk directory (LeRobot's DEFAULT_CHUNK_SIZE)."""
DATA_FILE_MB = 100
VIDEO_FILE_MB = 200
"""A new data (video) file is started once the current one reaches this size (LeRobot's defaults)."""
CHUNK_FILE = "chunk-{chunk_index:03d}/file-{file_index:03d}"
DATA_PATH = "data/" + CHUNK_FILE + ".parquet"
VIDEO_PATH = "videos/{video_key}/" + CHUNK_FILE + ".mp4"
EPISODES_PATH = "meta/episodes/" + CHUNK_FILE + ".parquet"
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
"""The quantiles LeRobot's stats hold, as q01 ... q99."""
IMAGE_STAT_SAMPLES = 100
"""Frames per episode that image statistics are computed over (LeRobot samples about as many)."""
VIDEO_CODEC = "libx264"
VIDEO_OPTIONS = {"crf": "18", "g": "2", "bf": "0"}
"""H.264 (LeRobot's default is AV1), a key frame every 2 frames as LeRobot encodes for random access."""
IMAGE_QUALITY = "full"
"""How the camera videos are drawn (`rendering.IMAGE_QUALITIES`): as the viewer shows the scene. LeRobot's env
(plugins/lerobot_env_fetch) draws its observation images the same way, so a policy sees there what it learnt on."""
ROBOT_TYPE = "fetch"
ACTION_NAMES = ("x", "y", "z", "gripper")
_REPO_ID = re.compile(r"^[A-Za-z0-9][-\w.]*/[-\w.]+$")


def lerobot_home() -> pathlib.Path:
    """Where LeRobot looks for `repo_id` when given no root: $HF_LEROBOT_HOME, else $HF_HOME/lerobot,
    else $XDG_CACHE_HOME/huggingface/lerobot, else ~/.cache/huggingface/lerobot. The first of these that
    is set decides; set but empty, it is an error (`dirs.env_dir`)."""
    default = "~/.cache/huggingface/lerobot"
    home = env_dir("HF_LEROBOT_HOME", default)
    if home is not None:
        return home.expanduser()
    hub = env_dir("HF_HOME", default)
    if hub is None:
        hub = (env_dir("XDG_CACHE_HOME", default) or pathlib.Path("~/.cache")) / "huggingface"
    return hub.expanduser() / "lerobot"


def check_repo_id(repo_id: str) -> None:
    if not _REPO_ID.match(repo_id):
        raise FetchError(f"bad --repo-id {repo_id!r}: it must read namespace/name (letters, digits, '-', '_', '.'), "
                         "as on the Hugging Face Hub, e.g. me/fetch_drawer_open")


def video_key(camera: str) -> str:
    return f"observation.images.{camera}"


def env_flags(env_id: str, cameras: Sequence[str], image_size: int, image_quality: str, hide_goal: bool) -> list[str]:
    """The `lerobot-eval` flags of the LeRobot env (plugins/lerobot_env_fetch) whose observations are these: the
    task, the cameras and, with cameras, their size and drawing, the goal's marker hidden or not."""
    flags = ["--env.type=fetch", f"--env.task={env_id}", f"--env.cameras={','.join(cameras) or 'none'}"]
    if cameras:
        flags += [f"--env.image_size={image_size}", f"--env.image_quality={image_quality}"]
    if hide_goal:
        flags.append("--env.hide_goal=true")
    return flags


# -- the layout ------------------------------------------------------------------------------------

ROBOT_PARTS = ("grip_pos", "gripper_state", "grip_velp", "gripper_vel")
"""The robot's own readings, parts of every task's observation layout: all that `observation.state` holds when
the dataset has camera images. A policy that sees is not handed the objects' poses; the goal stays in
`observation.environment_state` (the images show its marker too). Without cameras `observation.state` is the
whole observation vector. The table of both is in docs/lerobot_env.md."""


def state_layout(obs_layout: dict[str, slice], cameras: Sequence[str]) -> dict[str, slice]:
    """The slices of the observation vector that `observation.state` holds, in order: every part for a state
    policy (no `cameras`), the robot's own readings (`ROBOT_PARTS`) for a camera policy."""
    if not cameras:
        return dict(obs_layout)
    missing = [part for part in ROBOT_PARTS if part not in obs_layout]
    if missing:
        raise FetchError(f"the observation has no {', '.join(missing)} (its parts: {', '.join(obs_layout)})")
    return {part: obs_layout[part] for part in ROBOT_PARTS}


def state_index(layout: dict[str, slice]) -> np.ndarray:
    """The observation vector's indices of `layout`'s slices, side by side (int64)."""
    return np.concatenate([np.arange(s.start, s.stop) for s in layout.values()]).astype(np.int64)


def state_names(layout: dict[str, slice]) -> list[str]:
    """One name per value of the observation vector, from the env's `observation_layout` (grip_pos_x, ...)."""
    names = []
    for part, where in layout.items():
        size = where.stop - where.start
        suffixes = ("x", "y", "z") if size == 3 else tuple(str(i) for i in range(size))
        names += [part] if size == 1 else [f"{part}_{s}" for s in suffixes]
    return names


def features(obs_layout: dict[str, slice], cameras: Sequence[str], image_size: int,
             video_info: dict[str, Any], corrected: bool = False) -> dict[str, dict[str, Any]]:
    """`info.json`'s features: LeRobot's keys and dtypes, the frame indices last, as LeRobot orders them.
    `corrected`: some demos were corrected by a person (`--device takeover`), so `intervention` and
    `policy_action` columns follow `next.success`."""
    def vector(names: Sequence[str]) -> dict[str, Any]:
        return {"dtype": "float32", "shape": [len(names)], "names": list(names)}

    def scalar(dtype: str) -> dict[str, Any]:
        return {"dtype": dtype, "shape": [1], "names": None}

    out: dict[str, dict[str, Any]] = {
        "observation.state": vector(state_names(state_layout(obs_layout, cameras))),
        "observation.environment_state": vector(["goal_x", "goal_y", "goal_z"]),
        "action": vector(ACTION_NAMES),
        "executed_action": vector(ACTION_NAMES),
        "next.reward": scalar("float32"),
        "next.done": scalar("bool"),
        "next.success": scalar("bool"),
    }
    if corrected:
        out["intervention"] = scalar("bool")
        out["policy_action"] = vector(ACTION_NAMES)
    for camera in cameras:
        out[video_key(camera)] = {"dtype": "video", "shape": [image_size, image_size, 3],
                                  "names": ["height", "width", "channels"], "info": video_info}
    for key in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        out[key] = scalar("float32" if key == "timestamp" else "int64")
    return out


def frame_columns(arrays: dict[str, np.ndarray], episode: int, first_index: int, task: int,
                  fps: int, corrected: bool = False, state: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """One demo's rows of the data table, keyed as the features (without the videos). `state`: the indices of
    the observation vector that `observation.state` holds (`state_index`; None: all of it). With `corrected`,
    who drove each step (`intervention`: a person who took over from the policy; false throughout a demo
    recorded without takeover) and what the policy proposed (`policy_action`; the action itself where no
    policy was asked)."""
    t = len(arrays["actions"])
    observed = arrays["obs/observation"]
    frame = np.arange(t, dtype=np.int64)
    labels = {}
    if corrected:
        labels = {"intervention": np.asarray(arrays.get("intervention", np.zeros(t)), bool),
                  "policy_action": np.asarray(arrays.get("policy_actions", arrays["actions"]), np.float32)}
    return {
        "observation.state": (observed if state is None else observed[:, state]).astype(np.float32),
        "observation.environment_state": arrays["obs/desired_goal"].astype(np.float32),
        # What a policy imitates: what the device meant (the expert's clean action under DART
        # noise); the action the arm was given, which replays the demo, beside it.
        "action": schema.meant_actions(arrays),
        "executed_action": arrays["actions"].astype(np.float32),
        "next.reward": arrays["rewards"].astype(np.float32),
        "next.done": arrays["dones"].astype(bool),
        "next.success": arrays["is_success"].astype(bool),
        **labels,
        "timestamp": (frame / fps).astype(np.float32),
        "frame_index": frame,
        "episode_index": np.full(t, episode, np.int64),
        "index": first_index + frame,
        "task_index": np.full(t, task, np.int64),
    }


# -- statistics ------------------------------------------------------------------------------------

def feature_stats(values: np.ndarray) -> dict[str, list[Any]]:
    """min, max, mean, std, count and quantiles over the first axis ((N,) or (N, D) values; exact)."""
    x = values.astype(np.float64).reshape(len(values), -1)
    stats = {"min": x.min(0), "max": x.max(0), "mean": x.mean(0), "std": x.std(0)}
    for q in QUANTILES:
        stats[f"q{round(q * 100):02d}"] = np.quantile(x, q, axis=0)
    out: dict[str, list[Any]] = {k: v.tolist() for k, v in stats.items()}
    out["count"] = [len(values)]
    return out


def pixel_counts(frames: np.ndarray) -> np.ndarray:
    """How often each value 0-255 occurs in each channel of (N, H, W, 3) uint8 frames: (3, 256)."""
    channels = frames.reshape(-1, 3)
    return np.stack([np.bincount(channels[:, c], minlength=256) for c in range(3)])


def image_stats(counts: np.ndarray, images: int) -> dict[str, list[Any]]:
    """Per-channel statistics in [0, 1] of the pixels `pixel_counts` counted in `images` frames, each
    (3, 1, 1) as LeRobot keeps them; exact (the quantiles are numpy's linear ones) from the counts."""
    values = np.arange(256) / 255.0
    stats: dict[str, list[float]] = collections.defaultdict(list)
    for row in counts:
        n = int(row.sum())
        mean = float(row @ values) / n
        stats["min"].append(float(values[np.flatnonzero(row)[0]]))
        stats["max"].append(float(values[np.flatnonzero(row)[-1]]))
        stats["mean"].append(mean)
        stats["std"].append(float(np.sqrt(max(0.0, float(row @ values**2) / n - mean**2))))
        ends = np.cumsum(row)  # the order statistics k < ends[v] have value v
        for q in QUANTILES:
            position = q * (n - 1)
            below, above = np.floor(position), np.ceil(position)
            low, high = (values[np.searchsorted(ends, k, side="right")] for k in (below, above))
            stats[f"q{round(q * 100):02d}"].append(float(low + (position - below) * (high - low)))
    out: dict[str, list[Any]] = {k: [[[v]] for v in channel] for k, channel in stats.items()}
    out["count"] = [images]
    return out


def sample_rows(n: int, most: int = IMAGE_STAT_SAMPLES) -> np.ndarray:
    """Evenly spread frame indices for image statistics."""
    return np.unique(np.round(np.linspace(0, n - 1, min(n, most))).astype(int))


def check_export(env_id: str, env_kwargs: dict[str, Any], cameras: Sequence[str], image_size: int,
                 fps: float | None) -> int:
    """The frame rate to write (the control rate), after checking the arguments against the env, before any work."""
    import gymnasium as gym

    import fetch  # noqa: F401  (registers the ids)
    from fetch.rendering import check_camera, check_camera_list, check_image_size

    check_camera_list(cameras)
    check_image_size(image_size, "--image-size")
    env: Any = gym.make(env_id, **env_kwargs).unwrapped
    try:
        dt = float(env.dt)
        for camera in cameras:
            check_camera(env.model, camera)
    finally:
        env.close()
    rate = 1.0 / dt
    if fps is not None and not math.isclose(fps, rate):
        raise FetchError(f"--fps {fps:g}: a frame is one control step of {dt:g} s, so the dataset's rate is "
                         f"{rate:g} (LeRobot's timestamps are frame_index / fps); pass --fps {rate:g} or leave it out")
    if cameras and (image_size <= 0 or image_size % 2):
        raise FetchError(f"--image-size must be an even number of pixels (H.264 video), got {image_size}")
    return round(rate)
