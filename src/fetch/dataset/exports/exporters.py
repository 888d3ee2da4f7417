"""`gym-fetch export --to FORMAT`: one `Exporter` per format (`EXPORTERS`), and `export`, which runs the one an
`ExportRequest` names.

An exporter says which of the request's options it reads and which it needs; `export` refuses any other
before anything is read or written, with a line naming the formats that do read it, so adding a format is
one record here and its export function, not another branch.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

from fetch.dataset.exports.export import export_lerobot, export_minari, export_npz, minari_root
from fetch.errors import FetchError, UnknownNameError


@dataclasses.dataclass(frozen=True)
class ExportRequest:
    """An export: the dataset, the format, the common options, and each format's own (None: not given; the
    format's default where it reads the option, and refused where it does not)."""

    file: str
    """the dataset (a directory or file)."""
    to: str
    """the format, an `Exporter`'s name."""
    demos: str = "successful"
    """which demos: successful, all, or a mask of the file (train, valid, failed)."""
    force: bool = False
    """replace what is there (a Minari dataset of the same id, the directory at `out`)."""
    dataset_id: str | None = None
    """minari: (namespace/)name-v<version>."""
    out: str | None = None
    """npz: the directory for the files; lerobot: the dataset's root."""
    repo_id: str | None = None
    """lerobot: the dataset's namespace/name."""
    cameras: str | None = None
    """lerobot: cameras to render as videos, comma-separated ("none": no video)."""
    image_size: int | None = None
    """lerobot: video width and height [px]."""
    image_quality: str | None = None
    """lerobot: how the videos are drawn (`rendering.IMAGE_QUALITIES`)."""
    fps: float | None = None
    """lerobot: frames per second."""
    author: str | None = None
    """minari: the dataset's author."""
    author_email: str | None = None
    """minari: the author's e-mail address."""
    code_permalink: str | None = None
    """minari: a link to the code that made the data."""
    description: str | None = None
    """minari: what the demos are and where they came from."""


@dataclasses.dataclass(frozen=True)
class Exporter:
    name: str
    """`--to NAME`."""
    summary: str
    """what it writes, for `--help`."""
    reads: tuple[str, ...]
    """the options it reads besides the common ones (the file, `demos`, `force`): `ExportRequest` fields."""
    needs: Mapping[str, str]
    """the options it cannot do without, and what to give (for the error when one is missing)."""
    where: Callable[[], str]
    """where it writes, for the error that refuses an option it does not read."""
    run: Callable[[ExportRequest], str]
    """export as the request says; the line to print."""


def _minari(request: ExportRequest) -> str:
    if request.dataset_id is not None and not request.dataset_id.strip():
        raise FetchError("--dataset-id is empty; give one such as fetch/reach/expert-v0, or leave it out for the "
                         "default")
    done = export_minari(request.file, request.dataset_id, demos=request.demos, force=request.force,
                         author=request.author, author_email=request.author_email,
                         code_permalink=request.code_permalink, description=request.description)
    dataset_id = done.path.relative_to(minari_root()).as_posix()
    return f"wrote {len(done.demos)} demo(s), {done.steps} steps, as Minari dataset {dataset_id} in {done.path}"


def _npz(request: ExportRequest) -> str:
    assert request.out is not None  # needed: `export` checked
    done = export_npz(request.file, request.out, demos=request.demos, force=request.force)
    return f"wrote {len(done.demos)} demo(s), {done.steps} steps, as npz files in {done.path}"


def _lerobot(request: ExportRequest) -> str:
    assert request.repo_id is not None  # needed: `export` checked
    cameras = None if request.cameras is None else [c for c in request.cameras.split(",") if c and c != "none"]
    done = export_lerobot(request.file, request.repo_id, request.out, demos=request.demos, cameras=cameras,
                          image_size=request.image_size, image_quality=request.image_quality, fps=request.fps,
                          force=request.force)
    videos = f"; videos of {done.videos}" if done.videos else ""
    return (f"wrote {len(done.demos)} demo(s), {done.steps} frames, as LeRobotDataset {request.repo_id} in "
            f"{done.path}{videos}")


EXPORTERS: tuple[Exporter, ...] = (
    Exporter("minari", "a local Minari dataset",
             reads=("dataset_id", "author", "author_email", "code_permalink", "description"), needs={},
             where=lambda: f"--to minari writes under $MINARI_DATASETS_PATH (now {minari_root()}), named by "
                           "--dataset-id",
             run=_minari),
    Exporter("npz", "the files `collect --format npz` writes", reads=("out",),
             needs={"out": "--out DIR, the directory for the files"},
             where=lambda: "--to npz writes into --out DIR", run=_npz),
    Exporter("lerobot", "a LeRobotDataset v3.0 (parquet + mp4)",
             reads=("repo_id", "out", "cameras", "image_size", "image_quality", "fps"),
             needs={"repo_id": "--repo-id NAME (namespace/name, e.g. me/fetch_drawer_open)"},
             where=lambda: "--to lerobot names the dataset with --repo-id", run=_lerobot),
)
_BY_NAME = {e.name: e for e in EXPORTERS}
OPTIONS = tuple(dict.fromkeys(dest for e in EXPORTERS for dest in e.reads))
"""Every format-specific option, by its `ExportRequest` field."""


def _flag(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def export(request: ExportRequest) -> str:
    """Export as `request` says, after refusing an option its format does not read or a missing one it needs;
    the line that says what was written."""
    if request.to not in _BY_NAME:
        raise UnknownNameError("export format", request.to, tuple(_BY_NAME))
    exporter = _BY_NAME[request.to]
    for dest in OPTIONS:
        if getattr(request, dest, None) is not None and dest not in exporter.reads:
            readers = " or ".join(e.name for e in EXPORTERS if dest in e.reads)
            raise FetchError(f"{_flag(dest)} is for --to {readers}; {exporter.where()}")
    for dest, what in exporter.needs.items():
        if getattr(request, dest, None) is None:
            raise FetchError(f"--to {exporter.name} needs {what}")
    return exporter.run(request)
