"""Writing a LeRobotDataset v3.0 (see `lerobot`) with pyarrow and PyAV, without torch.

Frames go to one parquet file and one mp4 per camera, episode after episode, each file closed and
a new one started once it reaches LeRobot's size limit; the episodes' table, the tasks, the
statistics and `info.json` are written last. The whole dataset is built beside its target and
renamed into place at the end, so an interrupted export leaves the target as it was.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import pathlib
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from fetch._durable import NO_ROOM, why
from fetch.dataset.exports import lerobot
from fetch.dataset.exports.lerobot import video_key
from fetch.dataset.reader import Dataset
from fetch.dataset.schema import episode_seed, image_key, is_image
from fetch.errors import FetchError


@dataclasses.dataclass(frozen=True)
class Written:
    """What `write_lerobot` wrote: the dataset's directory, its frames and its video files."""

    path: pathlib.Path
    episodes: int
    frames: int
    videos: int
    stored_images: bool
    """Whether the videos show the dataset's own images (`uses_stored_images`) rather than ones drawn anew."""


def _imports() -> tuple[Any, Any, Any]:
    try:
        import av
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as e:
        raise FetchError(f"--to lerobot needs pyarrow and PyAV, which cannot be imported ({e}); install them "
                         f"with: {lerobot.INSTALL}") from e
    return pa, pq, av


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
        if self.file == lerobot.CHUNK_SIZE:
            self.chunk, self.file = self.chunk + 1, 0


class _Video:
    """One camera's mp4 files: frames are appended episode after episode, pts counting from each file's start."""

    def __init__(self, av: Any, root: pathlib.Path, key: str, fps: int, size: int) -> None:
        self.av, self.fps, self.size = av, fps, size
        self.files = _RollingFiles(root, lerobot.VIDEO_PATH, lerobot.VIDEO_FILE_MB, video_key=key)
        self.container: Any = None
        self.stream: Any = None
        self.frames_in_file = 0
        self.opened = 0

    def _open(self) -> None:
        path = self.files.path
        path.parent.mkdir(parents=True, exist_ok=True)
        self.container = self.av.open(str(path), "w", format="mp4")
        self.stream = self.container.add_stream(lerobot.VIDEO_CODEC, rate=self.fps, options=dict(lerobot.VIDEO_OPTIONS))
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


def write_lerobot(ds: Dataset, chosen: dict[str, dict[str, Any]], target: pathlib.Path, repo_id: str, *,
                  cameras: Sequence[str], image_size: int, fps: int, workers: int = 1, force: bool = False,
                  image_quality: str = lerobot.IMAGE_QUALITY) -> Written:
    """Write the `chosen` demos of `ds` (name -> attributes, in order) as a LeRobotDataset v3.0 at `target`, the
    videos drawn at `image_quality`.

    The dataset is built in a hidden directory beside `target` and renamed to it once complete; a
    replaced dataset (`force`) is removed only after that. Call `check_export` first for the arguments.
    """
    from fetch.dataset.dirs import replacing_dir

    pa, pq, av = _imports()
    try:
        with replacing_dir(pathlib.Path(target), force) as building:
            written = _write(pa, pq, av, ds, chosen, building, repo_id, cameras, image_size, image_quality, fps,
                             workers)
    except OSError as e:  # pyarrow's and PyAV's messages say it twice, or on several lines
        if e.errno not in NO_ROOM:
            raise
        raise FetchError(f"could not write the LeRobot dataset {target}: {why(e)}; nothing was written") from e
    return dataclasses.replace(written, path=pathlib.Path(target))


def _write(pa: Any, pq: Any, av: Any, ds: Dataset, chosen: dict[str, dict[str, Any]], root: pathlib.Path,
           repo_id: str, cameras: Sequence[str], size: int, quality: str, fps: int, workers: int) -> Written:
    import gymnasium as gym

    import fetch  # noqa: F401  (registers the ids)
    from fetch._progress import progress

    env: Any = gym.make(ds.env_id, **ds.env_kwargs).unwrapped
    obs_layout = dict(env.observation_layout)
    task = env.task.instruction
    env.close()
    state = lerobot.state_index(lerobot.state_layout(obs_layout, cameras))
    names = list(chosen)
    corrected = any("intervention" in ds.demo(name) for name in names)
    stored = uses_stored_images(ds, cameras, size, quality)
    wanted = {f"obs/{image_key(c)}" for c in cameras} if stored else set()
    videos = {camera: _Video(av, root, video_key(camera), fps, size) for camera in cameras}
    data_files = _RollingFiles(root, lerobot.DATA_PATH, lerobot.DATA_FILE_MB)
    writer: Any = None
    episodes: list[dict[str, Any]] = []
    columns_all: dict[str, list[np.ndarray]] = collections.defaultdict(list)
    pixels = {camera: np.zeros((3, 256), np.int64) for camera in cameras}
    sampled = 0
    frames = 0
    try:
        rendered = ({} for _ in names) if stored else _rendered(ds, names, cameras, size, quality, workers)
        for episode, (name, images) in enumerate(progress(zip(names, rendered, strict=True), len(names),
                                                          "export lerobot")):
            # Of a demo's images only those the videos take are read: they are most of its bytes.
            arrays = ds.arrays(name, keep=lambda path: not is_image(path) or path in wanted)
            if stored:
                images = {c: arrays[f"obs/{image_key(c)}"] for c in cameras}
            columns = lerobot.frame_columns(arrays, episode, frames, 0, fps, corrected, state)
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
                row.update({f"stats/{key}/{k}": v for k, v in lerobot.feature_stats(values).items()})
            rows = lerobot.sample_rows(length)
            sampled += len(rows)
            for camera in cameras:
                counts = lerobot.pixel_counts(images[camera][rows])
                pixels[camera] += counts
                episode_stats = lerobot.image_stats(counts, len(rows))
                row.update({f"stats/{video_key(camera)}/{k}": v for k, v in episode_stats.items()})
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
    stats = {key: lerobot.feature_stats(np.concatenate(parts)) for key, parts in columns_all.items()}
    stats.update({video_key(c): lerobot.image_stats(pixels[c], sampled) for c in cameras})
    info = lerobot.features(obs_layout, cameras, size, _video_info(av, root, cameras, fps), corrected)
    _write_meta(pa, pq, root, episodes, task, stats, info, frames, fps, cameras)
    _write_card(root, repo_id, ds, len(episodes), frames, task, cameras, size, quality, stored)
    return Written(root, len(episodes), frames, sum(v.opened for v in videos.values()), stored)


def _video_info(av: Any, root: pathlib.Path, cameras: Sequence[str], fps: int) -> dict[str, Any]:
    """The `info` of a video feature, read from the first file (LeRobot's `get_video_info`)."""
    if not cameras:
        return {}
    path = root / lerobot.VIDEO_PATH.format(video_key=video_key(cameras[0]), chunk_index=0, file_index=0)
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        return {"video.height": stream.height, "video.width": stream.width,
                "video.codec": stream.codec_context.codec.name, "video.pix_fmt": stream.pix_fmt,
                "video.is_depth_map": False, "video.fps": fps, "video.channels": 3, "has_audio": False}


def _write_meta(pa: Any, pq: Any, root: pathlib.Path, episodes: list[dict[str, Any]], task: str,
                stats: dict[str, Any], info_features: dict[str, Any], frames: int, fps: int,
                cameras: Sequence[str]) -> None:
    meta = root / "meta"
    path = root / lerobot.EPISODES_PATH.format(chunk_index=0, file_index=0)
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
        "codebase_version": lerobot.CODEBASE_VERSION, "robot_type": lerobot.ROBOT_TYPE,
        "total_episodes": len(episodes), "total_frames": frames, "total_tasks": 1, "chunks_size": lerobot.CHUNK_SIZE,
        "data_files_size_in_mb": lerobot.DATA_FILE_MB, "video_files_size_in_mb": lerobot.VIDEO_FILE_MB, "fps": fps,
        "splits": {"train": f"0:{len(episodes)}"}, "data_path": lerobot.DATA_PATH,
        "video_path": lerobot.VIDEO_PATH if cameras else None, "features": info_features,
    }
    (meta / "info.json").write_text(json.dumps(info, indent=4))


def _write_card(root: pathlib.Path, repo_id: str, ds: Dataset, episodes: int, frames: int, task: str,
                cameras: Sequence[str], size: int, quality: str, stored: bool) -> None:
    """A short README.md (the Hub's dataset card) saying what the data is (its videos: the `stored` images of the
    dataset, or drawn from its states), how to load it, and the env flags that give a policy learnt on it the same
    observations in `lerobot-eval` (the plugin's)."""
    env = " ".join(lerobot.env_flags(ds.env_id, cameras, size, quality, bool(ds.env_kwargs.get("hide_goal"))))
    source = "the dataset's own images" if stored else "from the saved states"
    drawn = (f"Videos of {', '.join(cameras)}, {size} x {size} px, drawn at image quality `{quality}`: {source}. "
             if cameras else "")
    (root / "README.md").write_text(
        "---\nlicense: mit\ntask_categories:\n- robotics\ntags:\n- LeRobot\n- gym-fetch-v2\nconfigs:\n"
        "- config_name: default\n  data_files: data/*/*.parquet\n---\n\n"
        f"# {repo_id}\n\n{episodes} `{ds.env_id}` demonstrations ({frames} frames at 25 fps), task \"{task}\", "
        f"exported by gym-fetch-v2 from `{ds.path.name}` (LeRobotDataset {lerobot.CODEBASE_VERSION}).\n\n"
        "```python\nfrom lerobot.datasets.lerobot_dataset import LeRobotDataset\n\n"
        f"dataset = LeRobotDataset(\"{repo_id}\", root=\"<this directory>\")\n```\n\n"
        f"{drawn}A policy learnt on it sees the same observations in `lerobot-eval {env}` (the `lerobot_env_fetch` "
        "plugin of gym-fetch-v2).\n")




def uses_stored_images(ds: Dataset, cameras: Sequence[str], size: int, quality: str) -> bool:
    """Whether the videos can be the dataset's own images, read rather than drawn again: it recorded every one
    of `cameras` at `size`, drawn at `quality`. The states would draw the same images (replay is exact);
    reading them is several times faster than rendering, and they are the very images a policy trained on the
    dataset learnt from. `require_valid` has made sure each demo holds them, one (size, size, 3) uint8 image a
    step."""
    layout = ds.layout
    return (bool(cameras) and set(cameras) <= set(layout.cameras) and layout.image_size == size
            and layout.image_quality == quality)


def _rendered(ds: Dataset, names: Sequence[str], cameras: Sequence[str], size: int, quality: str,
              workers: int) -> Iterator[dict[str, np.ndarray]]:
    """Each demo's frames per camera ((T, size, size, 3) uint8: the states before each step, drawn at `quality`),
    in order."""
    if not cameras:
        yield from ({} for _ in names)
        return
    from fetch.dataset.render.render_ahead import render_ahead

    jobs = ((name, ds.demo(name)["states"][:-1], episode_seed(ds.attrs(name))) for name in names)
    for images in render_ahead(ds.env_id, ds.env_kwargs, size, workers, jobs, cameras, quality):
        assert images is not None  # every demo has states
        yield images
