"""A dataset held by one tool at a time while it edits: which lock a collector's directory or a merged file
takes, and which files an interrupted edit's journal may rename (the mechanisms: `fetch._durable`)."""

from __future__ import annotations

import contextlib
import pathlib
from collections.abc import Callable, Iterator

from fetch._durable import finish_renames, journal_renames, lock_directory, lock_file, unlock_directory
from fetch.dataset import schema
from fetch.errors import DatasetError


@contextlib.contextmanager
def editing(index: pathlib.Path) -> Iterator[None]:
    """Hold a dataset while a tool reads and edits it: a collector's directory (it has `episodes/` beside
    `index`) itself, so no collector appends meanwhile; a single file (a merge's) by a lock file beside it
    (`.<name>.lock`, removed again when the edit ends), so two tools never edit it at once (render-obs
    and split on one merged file shared a temporary file: 5 of 6 crashed, once leaking images into it)."""
    if (index.parent / schema.EPISODES_DIR).is_dir():
        handle = lock_directory(index.parent, "run it when the collector has finished")
        lock = None
    else:
        if not index.exists():  # no lock file left behind for a dataset that is not there
            raise DatasetError(f"{index}: no such file")
        lock = index.with_name(f".{index.name}.lock")
        handle = lock_file(lock, index)
    try:
        finish_rewrites(index)
        yield
    finally:
        if lock is not None:  # while still held: whoever opens the name next makes a new file (see lock_file)
            with contextlib.suppress(OSError):
                lock.unlink()
        unlock_directory(handle)


def finish_rewrites(index: pathlib.Path) -> None:
    """Make the renames that an edit of the dataset at `index` stopped part-way through (a SIGKILL between
    them), if any; the caller holds the dataset (`editing`). A journal naming any other file than the index
    or a demo file in `episodes/` is refused whole, before anything is renamed (`interrupted_renames`)."""
    finish_renames(index, _ours(index), _described(index))


def interrupted_renames(index: pathlib.Path) -> list[tuple[pathlib.Path, pathlib.Path]] | None:
    """The renames (temporary file, file it replaces) an interrupted edit of the dataset at `index` noted
    (None: none), each checked to be one an edit of this dataset makes (`fetch._durable.journal_renames`)."""
    return journal_renames(index, _ours(index), _described(index))


def _ours(index: pathlib.Path) -> Callable[[pathlib.Path], bool]:
    """Whether a file is one an edit of the dataset at `index` replaces: the index, or a demo file."""
    return lambda path: path == index or (path.parent == index.parent / schema.EPISODES_DIR
                                          and _demo_file_name(path.name))


def _described(index: pathlib.Path) -> str:
    return f"{index.name} or {schema.EPISODES_DIR}/demo_<n>.hdf5"


def _demo_file_name(name: str) -> bool:
    stem, dot, suffix = name.partition(".")
    try:
        schema.demo_index(stem)
    except ValueError:
        return False
    return dot == "." and suffix == "hdf5"
