"""Files that survive a kill at any instant: written under a temporary name, flushed, renamed, the
directory flushed; several files replaced together; a directory held by one process at a time."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import pathlib
import shutil
from collections.abc import Iterator
from typing import Any

import h5py

from fetch._durable import atomic_write, fsync_path
from fetch.dataset import schema
from fetch.errors import DatasetError


def lock_directory(directory: pathlib.Path, alternative: str) -> Any:
    """Hold `directory` itself exclusively (an flock on the directory, until `unlock_directory`);
    DatasetError if another collector or tool holds it. `alternative` completes the message
    ("choose another --out"). A lock on a file inside could be bypassed by deleting the file."""
    return _held(os.open(directory, os.O_RDONLY | os.O_DIRECTORY),
                 f"{directory} is in use by another collector or tool (it holds the directory's lock); wait for "
                 f"it to finish or {alternative}")


def _held(fd: int, refusal: str) -> int:
    """`fd`, locked exclusively; DatasetError(`refusal`) (and `fd` closed) if another process holds it."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
        os.close(fd)
        raise DatasetError(refusal) from e
    return fd


def unlock_directory(handle: Any) -> None:
    with contextlib.suppress(OSError):
        fcntl.flock(handle, fcntl.LOCK_UN)
    with contextlib.suppress(OSError):
        os.close(handle)


@contextlib.contextmanager
def editing(index: pathlib.Path) -> Iterator[None]:
    """Hold a dataset while a tool reads and edits it: a collector's directory (it has `episodes/` beside
    `index`) itself, so no collector appends meanwhile; a single file (a merge's) by a lock file beside it
    (`.<name>.lock`), which outlives the file's replacement, so two tools never edit it at once (render-obs
    and split on one merged file shared a temporary file: 5 of 6 crashed, once leaking images into it)."""
    if (index.parent / schema.EPISODES_DIR).is_dir():
        handle = lock_directory(index.parent, "run it when the collector has finished")
    else:
        if not index.exists():  # no lock file left behind for a dataset that is not there
            raise DatasetError(f"{index}: no such file")
        handle = _lock_file(index.with_name(f".{index.name}.lock"), index)
    try:
        finish_rewrites(index)
        yield
    finally:
        unlock_directory(handle)


def journal_of(path: pathlib.Path) -> pathlib.Path:
    """Where `Rewrites` notes the renames it is making, beside the file it replaces last (an index)."""
    return path.with_name(f".{path.name}.rewrites")


def finish_rewrites(index: pathlib.Path) -> None:
    """Make the renames that a `Rewrites` stopped part-way through (a SIGKILL between them) noted
    beside `index`, if any; the caller holds the dataset (`editing`)."""
    journal = journal_of(index)
    try:
        renames = json.loads(journal.read_text())
    except FileNotFoundError:
        return
    except (OSError, ValueError) as e:
        raise DatasetError(f"{journal} (the renames of an interrupted edit) cannot be read: {e}; "
                           "remove it if the dataset reads as it should") from e
    for tmp, path in renames:
        if (index.parent / tmp).exists():  # renamed already otherwise
            os.replace(index.parent / tmp, index.parent / path)
    for directory in {(index.parent / path).parent for _, path in renames}:
        fsync_path(directory)
    journal.unlink()
    fsync_path(index.parent)


def _lock_file(lock: pathlib.Path, dataset: pathlib.Path) -> Any:
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as e:
        raise DatasetError(f"cannot lock {dataset} for editing ({lock}: {e.strerror})") from e
    return _held(fd, f"{dataset} is being edited by another tool (it holds {lock.name}); wait for it to finish")


class Rewrites:
    """Edits of HDF5 files that replace the originals together, when the block ends, or not at all.

    `edit(path)` yields a copy opened for writing; when the `with Rewrites()` block finishes, every
    copy is flushed and renamed over its original, in the order first edited (so edit an index
    last); if the block raises, the copies are deleted and no original has changed.
    """

    def __init__(self) -> None:
        self._copies: dict[pathlib.Path, pathlib.Path] = {}

    @contextlib.contextmanager
    def edit(self, path: pathlib.Path) -> Iterator[h5py.File]:
        tmp = self._copies.get(path)
        if tmp is None:
            tmp = path.with_name(f".{path.name}.tmp")
            self._copies[path] = tmp
            shutil.copyfile(path, tmp)
        with h5py.File(tmp, "r+") as f:
            yield f

    def __enter__(self) -> Rewrites:
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        try:
            if kind is None and self._copies:
                for tmp in self._copies.values():
                    fsync_path(tmp)
                # Noted first, so that a kill between the renames is finished by the next tool to hold
                # the dataset (`finish_rewrites`), not left half old, half new (some demos with images
                # and a layout without the camera).
                last = list(self._copies)[-1]
                journal = journal_of(last)
                renames = [[os.path.relpath(tmp, last.parent), os.path.relpath(path, last.parent)]
                           for path, tmp in self._copies.items()]
                atomic_write(journal, json.dumps(renames).encode())
                for path, tmp in self._copies.items():
                    os.replace(tmp, path)
                for directory in {path.parent for path in self._copies}:
                    fsync_path(directory)
                journal.unlink()
        finally:
            for tmp in self._copies.values():
                with contextlib.suppress(OSError):
                    tmp.unlink()


@contextlib.contextmanager
def rewritten(path: pathlib.Path) -> Iterator[h5py.File]:
    """Edit one HDF5 file all at once (see `Rewrites`)."""
    with Rewrites() as rewrites, rewrites.edit(path) as f:
        yield f
