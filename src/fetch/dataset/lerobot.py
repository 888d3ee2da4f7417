"""A LeRobotDataset v3.0 (parquet tables, one mp4 per camera, JSON metadata) written without torch.

The layout is LeRobot's (`lerobot.datasets.utils`, release 0.4.4): `data/chunk-000/file-000.parquet` holds
one row per frame, `videos/<key>/chunk-000/file-000.mp4` the frames of every episode one after another,
`meta/episodes/chunk-000/file-000.parquet` one row per episode (where its rows and frames are, its
statistics), `meta/tasks.parquet` the task strings, `meta/stats.json` and `meta/info.json`. A frame is
one control step: the observation before step t, the action of step t and what step t gave
(`next.reward`, `next.done`, `next.success`); the state after the last step has no frame. Images are
rendered from the saved states. The dataset is written beside its target and renamed into place at the
end, so an interrupted export leaves the target as it was.
"""

from __future__ import annotations

import collections
import concurrent.futures
import dataclasses
import json
import math
import os
import pathlib
import re
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from fetch.dataset.reader import Dataset
from fetch.errors import DatasetError, FetchError

CODEBASE_VERSION = "v3.0"
INSTALL = 'pip install "gym-fetch-v2[lerobot]"'
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
ROBOT_TYPE = "fetch"
INSTRUCTIONS: dict[str, str] = {
    "Bin-pick-v2": "pick the block out of the bin and bring it to the goal",
    "Bin-place-v2": "put the block into the bin",
    "Box-open-v2": "take the lid off the box and set it down beside the box",
    "Box-close-v2": "put the lid on the box",
    "Drawer-open-v2": "open the drawer",
    "Drawer-close-v2": "close the drawer",
    "Reach-v2": "move the gripper to the goal",
    "Push-v2": "push the block to the goal",
    "PickPlace-v2": "pick up the block and bring it to the goal",
    "Slide-v2": "slide the puck to the goal",
}
"""The task string of each env id (LeRobot's `task`, what a language-conditioned policy reads)."""
ACTION_NAMES = ("x", "y", "z", "gripper")
_REPO_ID = re.compile(r"^[A-Za-z0-9][-\w.]*/[-\w.]+$")


@dataclasses.dataclass(frozen=True)
class Written:
    """What `write_lerobot` wrote: the dataset's directory, its frames and its video files."""

    path: pathlib.Path
    episodes: int
    frames: int
    videos: int


def lerobot_home() -> pathlib.Path:
    """Where LeRobot looks for `repo_id` when given no root: $HF_LEROBOT_HOME, else $HF_HOME/lerobot,
    else $XDG_CACHE_HOME/huggingface/lerobot, else ~/.cache/huggingface/lerobot."""
    if "HF_LEROBOT_HOME" in os.environ:
        return pathlib.Path(os.environ["HF_LEROBOT_HOME"]).expanduser()
    cache = pathlib.Path(os.environ.get("XDG_CACHE_HOME", "~/.cache")).expanduser()
    return pathlib.Path(os.environ.get("HF_HOME", cache / "huggingface")).expanduser() / "lerobot"


def check_repo_id(repo_id: str) -> None:
    if not _REPO_ID.match(repo_id):
        raise FetchError(f"bad --repo-id {repo_id!r}: it must read namespace/name (letters, digits, '-', '_', '.'), "
                         "as on the Hugging Face Hub, e.g. me/fetch_drawer_open")


def video_key(camera: str) -> str:
    return f"observation.images.{camera}"


def _imports() -> tuple[Any, Any, Any]:
    try:
        import av
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as e:
        raise FetchError(f"--to lerobot needs pyarrow and PyAV, which cannot be imported ({e}); install them "
                         f"with: {INSTALL}") from e
    return pa, pq, av


# -- the layout ------------------------------------------------------------------------------------

def state_names(layout: dict[str, slice]) -> list[str]:
    """One name per value of the observation vector, from the env's `observation_layout` (grip_pos_x, ...)."""
    names = []
    for part, where in layout.items():
        size = where.stop - where.start
        suffixes = ("x", "y", "z") if size == 3 else tuple(str(i) for i in range(size))
        names += [part] if size == 1 else [f"{part}_{s}" for s in suffixes]
    return names


def features(obs_layout: dict[str, slice], cameras: Sequence[str], image_size: int,
             video_info: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """`info.json`'s features: LeRobot's keys and dtypes, the frame indices last, as LeRobot orders them."""
    def vector(names: Sequence[str]) -> dict[str, Any]:
        return {"dtype": "float32", "shape": [len(names)], "names": list(names)}

    def scalar(dtype: str) -> dict[str, Any]:
        return {"dtype": dtype, "shape": [1], "names": None}

    out: dict[str, dict[str, Any]] = {
        "observation.state": vector(state_names(obs_layout)),
        "observation.environment_state": vector(["goal_x", "goal_y", "goal_z"]),
        "action": vector(ACTION_NAMES),
        "next.reward": scalar("float32"),
        "next.done": scalar("bool"),
        "next.success": scalar("bool"),
    }
    for camera in cameras:
        out[video_key(camera)] = {"dtype": "video", "shape": [image_size, image_size, 3],
                                  "names": ["height", "width", "channels"], "info": video_info}
    for key in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        out[key] = scalar("float32" if key == "timestamp" else "int64")
    return out


def frame_columns(arrays: dict[str, np.ndarray], episode: int, first_index: int, task: int,
                  fps: int) -> dict[str, np.ndarray]:
    """One demo's rows of the data table, keyed as the features (without the videos)."""
    t = len(arrays["actions"])
    frame = np.arange(t, dtype=np.int64)
    return {
        "observation.state": arrays["obs/observation"].astype(np.float32),
        "observation.environment_state": arrays["obs/desired_goal"].astype(np.float32),
        "action": arrays["actions"].astype(np.float32),
        "next.reward": arrays["rewards"].astype(np.float32),
        "next.done": arrays["dones"].astype(bool),
        "next.success": arrays["is_success"].astype(bool),
        "timestamp": (frame / fps).astype(np.float32),
        "frame_index": frame,
        "episode_index": np.full(t, episode, np.int64),
        "index": first_index + frame,
        "task_index": np.full(t, task, np.int64),
    }


def _arrow_table(pa: Any, columns: dict[str, np.ndarray]) -> Any:
    """Vectors as fixed-size lists and (1,)-shaped features as plain values, as `datasets` stores them."""
    arrays = {}
    for key, values in columns.items():
        if values.ndim == 2:
            flat = pa.array(values.reshape(-1))
            arrays[key] = pa.FixedSizeListArray.from_arrays(flat, values.shape[1])
        else:
            arrays[key] = pa.array(values)
    return pa.table(arrays)


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


def image_stats(frames: np.ndarray) -> dict[str, list[Any]]:
    """Per-channel statistics of (N, H, W, 3) uint8 frames in [0, 1], each (3, 1, 1) as LeRobot keeps them."""
    pixels = frames.reshape(-1, 3).astype(np.float64) / 255.0
    flat = feature_stats(pixels)
    out: dict[str, list[Any]] = {k: [[[v]] for v in values] for k, values in flat.items() if k != "count"}
    out["count"] = [len(frames)]
    return out


def sample_rows(n: int, most: int = IMAGE_STAT_SAMPLES) -> np.ndarray:
    """Evenly spread frame indices for image statistics."""
    return np.unique(np.round(np.linspace(0, n - 1, min(n, most))).astype(int))


# -- writing ---------------------------------------------------------------------------------------

class _RollingFiles:
    """Numbered files (chunk-XXX/file-YYY) in `root`; a new one is started once one reaches `limit_mb`."""

    def __init__(self, root: pathlib.Path, pattern: str, limit_mb: float, **names: str) -> None:
        self.root, self.pattern, self.limit, self.names = root, pattern, limit_mb * 1024 * 1024, names
        self.chunk = self.file = 0

    @property
    def path(self) -> pathlib.Path:
        return self.root / self.pattern.format(chunk_index=self.chunk, file_index=self.file, **self.names)

    def full(self) -> bool:
        return self.path.exists() and self.path.stat().st_size >= self.limit

    def advance(self) -> None:
        self.file += 1
        if self.file == CHUNK_SIZE:
            self.chunk, self.file = self.chunk + 1, 0


class _Video:
    """One camera's mp4 files: frames are appended episode after episode, pts counting from each file's start."""

    def __init__(self, av: Any, root: pathlib.Path, key: str, fps: int, size: int) -> None:
        self.av, self.fps, self.size = av, fps, size
        self.files = _RollingFiles(root, VIDEO_PATH, VIDEO_FILE_MB, video_key=key)
        self.container: Any = None
        self.stream: Any = None
        self.frames_in_file = 0
        self.opened = 0

    def _open(self) -> None:
        path = self.files.path
        path.parent.mkdir(parents=True, exist_ok=True)
        self.container = self.av.open(str(path), "w", format="mp4")
        self.stream = self.container.add_stream(VIDEO_CODEC, rate=self.fps, options=dict(VIDEO_OPTIONS))
        self.stream.width = self.stream.height = self.size
        self.stream.pix_fmt = "yuv420p"
        self.frames_in_file = 0
        self.opened += 1

    def add_episode(self, frames: np.ndarray) -> dict[str, Any]:
        """Append one episode's (T, H, W, 3) frames; where they are (LeRobot's videos/<key>/... columns)."""
        if self.container is not None and self.files.full():
            self.close()
            self.files.advance()
        if self.container is None:
            self._open()
        start = self.frames_in_file
        for image in frames:
            frame = self.av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="rgb24")
            frame.pts = self.frames_in_file
            for packet in self.stream.encode(frame):
                self.container.mux(packet)
            self.frames_in_file += 1
        return {"chunk_index": self.files.chunk, "file_index": self.files.file, "from_timestamp": start / self.fps,
                "to_timestamp": self.frames_in_file / self.fps}

    def close(self) -> None:
        if self.container is not None:
            for packet in self.stream.encode():
                self.container.mux(packet)
            self.container.close()
            self.container = self.stream = None


def _rendered(ds: Dataset, names: Sequence[str], cameras: Sequence[str], size: int,
              workers: int) -> Iterator[dict[str, np.ndarray]]:
    """Each demo's frames per camera ((T, size, size, 3) uint8, the states before each step), in order."""
    if not cameras:
        for _ in names:
            yield {}
        return
    from fetch.dataset.frames import RenderPool

    with RenderPool(ds.env_id, ds.env_kwargs, size, workers) as pool:
        queue = iter(names)
        pending: collections.deque[concurrent.futures.Future[dict[str, np.ndarray]]] = collections.deque()

        def submit_next() -> None:
            name = next(queue, None)
            if name is not None:
                pending.append(pool.submit(ds.demo(name)["states"][:-1], tuple(cameras)))

        for _ in range(2 * workers):  # a few demos ahead, not every demo's images at once
            submit_next()
        try:
            while pending:
                try:
                    images = pending.popleft().result()
                except concurrent.futures.process.BrokenProcessPool as e:
                    raise DatasetError(f"a render worker died: {e}") from e
                submit_next()
                yield images
        finally:
            for future in pending:
                future.cancel()


def write_lerobot(ds: Dataset, chosen: dict[str, dict[str, Any]], target: pathlib.Path, repo_id: str, *,
                  cameras: Sequence[str], image_size: int, fps: int, workers: int = 1, force: bool = False) -> Written:
    """Write the `chosen` demos of `ds` (name -> attributes, in order) as a LeRobotDataset v3.0 at `target`.

    The dataset is built in a hidden directory beside `target` and renamed to it once complete; a
    replaced dataset (`force`) is removed only after that. Call `check_export` first for the arguments.
    """
    from fetch.dataset.dirs import replacing_dir

    pa, pq, av = _imports()
    with replacing_dir(pathlib.Path(target), force) as building:
        written = _write(pa, pq, av, ds, chosen, building, repo_id, cameras, image_size, fps, workers)
    return dataclasses.replace(written, path=pathlib.Path(target))


def _write(pa: Any, pq: Any, av: Any, ds: Dataset, chosen: dict[str, dict[str, Any]], root: pathlib.Path,
           repo_id: str, cameras: Sequence[str], size: int, fps: int, workers: int) -> Written:
    import gymnasium as gym

    import fetch  # noqa: F401  (registers the ids)
    from fetch._progress import progress

    env: Any = gym.make(ds.env_id, **ds.env_kwargs).unwrapped
    obs_layout = dict(env.observation_layout)
    env.close()
    task = INSTRUCTIONS[ds.env_id]
    names = list(chosen)
    videos = {camera: _Video(av, root, video_key(camera), fps, size) for camera in cameras}
    data_files = _RollingFiles(root, DATA_PATH, DATA_FILE_MB)
    writer: Any = None
    episodes: list[dict[str, Any]] = []
    columns_all: dict[str, list[np.ndarray]] = collections.defaultdict(list)
    image_samples: dict[str, list[np.ndarray]] = collections.defaultdict(list)
    frames = 0
    try:
        rendered = _rendered(ds, names, cameras, size, workers)
        for episode, (name, images) in enumerate(progress(zip(names, rendered, strict=True), len(names),
                                                          "export lerobot")):
            columns = frame_columns(ds.arrays(name), episode, frames, 0, fps)
            length = len(columns["index"])
            if writer is not None and data_files.full():
                writer.close()
                writer = None
                data_files.advance()
            table = _arrow_table(pa, columns)
            if writer is None:
                data_files.path.parent.mkdir(parents=True, exist_ok=True)
                writer = pq.ParquetWriter(str(data_files.path), table.schema, compression="snappy")
            writer.write_table(table)
            row: dict[str, Any] = {
                "episode_index": episode, "tasks": [task], "length": length,
                "data/chunk_index": data_files.chunk, "data/file_index": data_files.file,
                "dataset_from_index": frames, "dataset_to_index": frames + length,
            }
            for camera, video in videos.items():
                where = video.add_episode(images[camera])
                row.update({f"videos/{video_key(camera)}/{k}": v for k, v in where.items()})
            for key, values in columns.items():
                columns_all[key].append(values)
                row.update({f"stats/{key}/{k}": v for k, v in feature_stats(values).items()})
            for camera in cameras:
                sample = images[camera][sample_rows(length)]
                image_samples[camera].append(sample)
                row.update({f"stats/{video_key(camera)}/{k}": v for k, v in image_stats(sample).items()})
            attrs = chosen[name]
            row.update({"meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0, "gym_fetch/demo": name,
                        "gym_fetch/seed": int(attrs["seed"]), "gym_fetch/device": str(attrs.get("device", "")),
                        "gym_fetch/success": bool(attrs["success"])})
            episodes.append(row)
            frames += length
    finally:
        if writer is not None:
            writer.close()
        for video in videos.values():
            video.close()
    stats = {key: feature_stats(np.concatenate(parts)) for key, parts in columns_all.items()}
    stats.update({video_key(c): image_stats(np.concatenate(image_samples[c])) for c in cameras})
    info = features(obs_layout, cameras, size, _video_info(av, root, cameras, fps))
    _write_meta(pa, pq, root, episodes, task, stats, info, frames, fps, cameras)
    _write_card(root, repo_id, ds, len(episodes), frames, task)
    return Written(root, len(episodes), frames, sum(v.opened for v in videos.values()))


def _video_info(av: Any, root: pathlib.Path, cameras: Sequence[str], fps: int) -> dict[str, Any]:
    """The `info` of a video feature, read from the first file (LeRobot's `get_video_info`)."""
    if not cameras:
        return {}
    path = root / VIDEO_PATH.format(video_key=video_key(cameras[0]), chunk_index=0, file_index=0)
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        return {"video.height": stream.height, "video.width": stream.width,
                "video.codec": stream.codec_context.codec.name, "video.pix_fmt": stream.pix_fmt,
                "video.is_depth_map": False, "video.fps": fps, "video.channels": 3, "has_audio": False}


def _write_meta(pa: Any, pq: Any, root: pathlib.Path, episodes: list[dict[str, Any]], task: str,
                stats: dict[str, Any], info_features: dict[str, Any], frames: int, fps: int,
                cameras: Sequence[str]) -> None:
    meta = root / "meta"
    path = root / EPISODES_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = list(episodes[0])
    pq.write_table(pa.table({k: [row[k] for row in episodes] for k in keys}), str(path), compression="snappy")
    # pandas' layout for a frame indexed by the task strings, which is how LeRobot reads it back
    pandas_meta = {"index_columns": ["__index_level_0__"], "column_indexes": [], "columns": [
        {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64",
         "metadata": None},
        {"name": None, "field_name": "__index_level_0__", "pandas_type": "unicode", "numpy_type": "object",
         "metadata": None}], "creator": {"library": "gym-fetch-v2"}, "pandas_version": "2.2.3"}
    tasks = pa.table({"task_index": pa.array([0], pa.int64()), "__index_level_0__": pa.array([task])})
    tasks = tasks.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})
    pq.write_table(tasks, str(meta / "tasks.parquet"))
    (meta / "stats.json").write_text(json.dumps(stats, indent=4))
    info = {
        "codebase_version": CODEBASE_VERSION, "robot_type": ROBOT_TYPE, "total_episodes": len(episodes),
        "total_frames": frames, "total_tasks": 1, "chunks_size": CHUNK_SIZE, "data_files_size_in_mb": DATA_FILE_MB,
        "video_files_size_in_mb": VIDEO_FILE_MB, "fps": fps, "splits": {"train": f"0:{len(episodes)}"},
        "data_path": DATA_PATH, "video_path": VIDEO_PATH if cameras else None, "features": info_features,
    }
    (meta / "info.json").write_text(json.dumps(info, indent=4))


def _write_card(root: pathlib.Path, repo_id: str, ds: Dataset, episodes: int, frames: int, task: str) -> None:
    """A short README.md (the Hub's dataset card) saying what the data is and how to load it."""
    (root / "README.md").write_text(
        "---\nlicense: mit\ntask_categories:\n- robotics\ntags:\n- LeRobot\n- gym-fetch-v2\nconfigs:\n"
        "- config_name: default\n  data_files: data/*/*.parquet\n---\n\n"
        f"# {repo_id}\n\n{episodes} `{ds.env_id}` demonstrations ({frames} frames at 25 fps), task \"{task}\", "
        f"exported by gym-fetch-v2 from `{ds.path.name}` (LeRobotDataset {CODEBASE_VERSION}).\n\n"
        "```python\nfrom lerobot.datasets.lerobot_dataset import LeRobotDataset\n\n"
        f"dataset = LeRobotDataset(\"{repo_id}\", root=\"<this directory>\")\n```\n")


def check_export(env_id: str, env_kwargs: dict[str, Any], cameras: Sequence[str], image_size: int,
                 fps: float | None) -> int:
    """The frame rate to write (the control rate), after checking the arguments against the env, before any work."""
    import gymnasium as gym

    import fetch  # noqa: F401  (registers the ids)
    from fetch.rendering import check_camera

    if env_id not in INSTRUCTIONS:
        raise FetchError(f"no LeRobot task string for {env_id}; add one to fetch.dataset.lerobot.INSTRUCTIONS")
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
    for camera in cameras:
        if list(cameras).count(camera) > 1:
            raise FetchError(f"--cameras names {camera} twice")
    return round(rate)
