"""A static web page of a dataset (`gym-fetch view`; it opens from disk, no server, no network).

The page lists every demo with a looping video rendered from its saved states, its length, seed,
device, session and success/valid flags, draws the selected demo's actions and observations over
time, and histograms of lengths and of success per device and per session. It is written beside
`--out` and renamed into place when complete.
"""

from __future__ import annotations

import collections
import dataclasses
import datetime
import os
import pathlib
from collections.abc import Iterator
from typing import Any

import numpy as np

from fetch.dataset.habits import FLAG_KINDS, dataset_flags
from fetch.dataset.reader import READ_ERRORS, Dataset, one_line, open_dataset, runs
from fetch.dataset.schema import episode_seed
from fetch.dataset.validation import validate
from fetch.errors import DatasetError, FetchError
from fetch.rendering import check_image_size

SIGNIFICANT = 5
"""Digits kept of each plotted value (the page's data files stay small)."""


_UNREADABLE: tuple[type[Exception], ...] = (DatasetError, *READ_ERRORS)


@dataclasses.dataclass(frozen=True)
class ViewReport:
    path: pathlib.Path
    demos: int
    videos: int
    invalid: int
    """demos with a problem."""
    file_problems: int
    """problems of the file that are no one demo's (its masks, its total, its header)."""


@dataclasses.dataclass(frozen=True)
class _Row:
    """One demo as the page's table shows it."""

    name: str
    length: int
    seed: int | str
    device: str
    session: str
    success: bool
    valid: bool
    problem: str
    readable: bool


def demo_problems(problems: list[str], names: list[str]) -> dict[str, list[str]]:
    """The problems `validate` found, by the demo each starts with (`demo_3: ...`, `demo_3 is in ...`)."""
    found: dict[str, list[str]] = collections.defaultdict(list)
    known = set(names)
    for problem in problems:
        head = problem.split(":", 1)[0].split(" ", 1)[0]
        if head in known:
            found[head].append(problem)
    return found


def session_of(attrs: dict[str, Any]) -> str:
    """What `success by session` groups by: the dataset a merged demo came from, else the UTC day it was
    recorded (a resumed collection on another day is another session)."""
    source = attrs.get("source")
    if isinstance(source, str) and ":" in source:
        return pathlib.Path(source.rsplit(":", 1)[0]).name
    started = attrs.get("started")
    if isinstance(started, int | float) and np.isfinite(started):
        return datetime.datetime.fromtimestamp(float(started), datetime.timezone.utc).strftime("%Y-%m-%d")
    return "?"


def _row(ds: Dataset, name: str, problems: list[str]) -> _Row:
    try:
        attrs = ds.attrs(name)
    except DatasetError as e:
        return _Row(name, 0, "?", "?", "?", False, False, str(e), False)
    length = attrs.get("num_samples", 0)
    readable = not any("cannot be read" in p or "missing" in p for p in problems)
    return _Row(name=name, length=int(length) if isinstance(length, int | np.integer) else 0,
                seed=int(attrs["seed"]) if isinstance(attrs.get("seed"), int | np.integer) else "?",
                device=str(attrs.get("device", "?")), session=session_of(attrs), success=bool(attrs.get("success")),
                valid=not problems, problem="; ".join(problems)[:500], readable=readable)


def _rounded(values: np.ndarray) -> list[Any]:
    """Columns of `values` ((T,) or (T, D)) as lists, to SIGNIFICANT digits, non-finite values as null."""
    array = np.asarray(values, dtype=np.float64)
    array = array[:, None] if array.ndim == 1 else array
    columns = []
    for column in array.T:
        columns.append([float(f"{v:.{SIGNIFICANT}g}") if np.isfinite(v) else None for v in column])
    return columns


def series(arrays: dict[str, np.ndarray], obs_layout: dict[str, slice]) -> dict[str, Any]:
    """What the page plots for one demo: actions, reward and success per step, each observation part over
    the T+1 observations (before every step and after the last), and where a person took over."""
    observation = np.concatenate([arrays["obs/observation"], arrays["next_obs/observation"][-1:]])
    return {"actions": _rounded(arrays["actions"]), "reward": _rounded(arrays["rewards"])[0],
            "success": _rounded(arrays["is_success"])[0],
            "obs": {part: _rounded(observation[:, where]) for part, where in obs_layout.items()},
            "takeovers": [list(r) for r in runs(arrays["intervention"])] if "intervention" in arrays else []}


def build_view(ds_path: str | os.PathLike[str], out: str | os.PathLike[str], *, camera: str = "front",
               size: int = 128, workers: int | None = None, force: bool = False) -> ViewReport:
    """Write the page (`index.html`), one mp4 per demo (`videos/`) and the demos' series (`data/`) to `out`, the
    videos `size` pixels square, rendered by `workers` processes (None: one per core)."""
    import gymnasium as gym

    import fetch  # noqa: F401  (registers the ids)
    from fetch._progress import progress
    from fetch.dataset.dirs import replacing_dir, require_apart
    from fetch.dataset.page.view_page import data_script, page
    from fetch.dataset.render.frames import check_env_camera
    from fetch.dataset.render.video import check_video_path
    from fetch.dataset.replay.render_obs import default_workers

    if workers is not None and workers < 1:
        raise FetchError(f"--workers must be at least 1, got {workers}")
    check_image_size(size, "--size")
    if size % 2:
        raise FetchError(f"--size must be an even number of pixels (H.264 video), got {size}")
    require_apart(out, [ds_path])
    with open_dataset(ds_path) as ds:
        if ds.env_id not in fetch.ENV_IDS:
            raise DatasetError(f"{ds.path}: its env {ds.env_id!r} is not one of gym-fetch-v2's; "
                               f"`gym-fetch info {ds.path}` lists what is wrong")
        try:  # without the env there is no page: its videos and plots need it
            env: Any = gym.make(ds.env_id, **ds.env_kwargs).unwrapped
        except Exception as e:  # noqa: BLE001 (the env's own check of its arguments, whatever it raises)
            raise DatasetError(f"{ds.path}: its env_kwargs {ds.env_kwargs!r} are refused by {ds.env_id} "
                               f"({one_line(e)}); `gym-fetch info {ds.path}` lists what is wrong") from e
        check_env_camera(ds.env_id, ds.env_kwargs, camera)
        obs_layout, fps = dict(env.observation_layout), round(1.0 / env.dt)
        env.close()
        names = list(ds.demo_names)
        found = validate(ds)
        problems = demo_problems(found, names)
        of_demos = {p for listed in problems.values() for p in listed}
        file_problems = [p for p in found if p not in of_demos]
        rows = [_row(ds, name, problems.get(name, [])) for name in names]
        flagged = dataset_flags(ds)
        with replacing_dir(pathlib.Path(out), force) as root:
            (root / "videos").mkdir()
            (root / "data").mkdir()
            check_video_path(root / "videos" / "check.mp4", size, size)
            videos = 0
            entries = []
            frames = _frames(ds, [r.name for r in rows if r.readable], camera, size, workers or default_workers())
            for row in progress(rows, len(rows), "view"):
                entry = {**dataclasses.asdict(row), "video": None, "data": None,
                         "flags": [f.as_dict() for f in flagged.get(row.name, [])]}
                if row.readable:
                    images = next(frames)
                    if images is not None:
                        _video(root / "videos" / f"{row.name}.mp4", images, fps, size)
                        entry["video"] = f"videos/{row.name}.mp4"
                        videos += 1
                    try:
                        data = series(ds.arrays(row.name), obs_layout)
                    except (DatasetError, KeyError, ValueError):
                        data = None
                    if data is not None:
                        (root / "data" / f"{row.name}.js").write_text(data_script(row.name, data))
                        entry["data"] = f"data/{row.name}.js"
                entries.append(entry)
            summary = {"env_id": ds.env_id, "path": str(ds.path), "camera": camera, "fps": fps, "demos": entries,
                       "flag_kinds": FLAG_KINDS, "problems": file_problems}
            (root / "index.html").write_text(page(summary, f"{ds.env_id}: {ds.path}"))
    return ViewReport(pathlib.Path(out), len(rows), videos, sum(not r.valid for r in rows), len(file_problems))


def _frames(ds: Dataset, names: list[str], camera: str, size: int, workers: int) -> Iterator[np.ndarray | None]:
    """Each demo's images of every saved state (None where the states cannot be read or are not finite)."""
    from fetch.dataset.render.render_ahead import render_ahead

    def states(name: str) -> np.ndarray | None:
        try:
            array = np.asarray(ds.demo(name)["states"][()], dtype=np.float64)
        except _UNREADABLE:
            return None
        ok = array.ndim == 2 and array.shape[1] == ds.layout.state_size and np.all(np.isfinite(array))
        return array if ok and len(array) else None

    drawn = ds.env_kwargs.get("looks") == "random"  # the images need each demo's seed (`fetch.looks`)
    jobs = ((name, states(name), episode_seed(ds.attrs(name)) if drawn else None) for name in names)
    for images in render_ahead(ds.env_id, ds.env_kwargs, size, min(workers, max(1, len(names))), jobs, (camera,)):
        yield None if images is None else images[camera]


def _video(path: pathlib.Path, images: np.ndarray, fps: int, size: int) -> None:
    from fetch.dataset.render.video import write_video

    write_video(path, iter(images), fps, size, size)


def describe(report: ViewReport) -> str:
    index = report.path / "index.html"
    problems = f", {report.file_problems} problem(s) of the file" if report.file_problems else ""
    return (f"wrote a page of {report.demos} demo(s) ({report.videos} videos, {report.invalid} invalid{problems}) to "
            f"{index}; open it in a browser (file://{index.resolve()})")
