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

from fetch._confine import inside, require_no_link, require_plain_file
from fetch._durable import atomic_write, fsync_path, temporary
from fetch.dataset import schema
from fetch.errors import DatasetError, OutsideError, one_line


class BusyError(DatasetError):
    """Another collector or tool holds the dataset."""


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
        raise BusyError(refusal) from e
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
    (`.<name>.lock`, removed again when the edit ends), so two tools never edit it at once (render-obs
    and split on one merged file shared a temporary file: 5 of 6 crashed, once leaking images into it)."""
    if (index.parent / schema.EPISODES_DIR).is_dir():
        handle = lock_directory(index.parent, "run it when the collector has finished")
        lock = None
    else:
        if not index.exists():  # no lock file left behind for a dataset that is not there
            raise DatasetError(f"{index}: no such file")
        lock = index.with_name(f".{index.name}.lock")
        handle = _lock_file(lock, index)
    try:
        finish_rewrites(index)
        yield
    finally:
        if lock is not None:  # while still held: whoever opens the name next makes a new file (see _lock_file)
            with contextlib.suppress(OSError):
                lock.unlink()
        unlock_directory(handle)


def journal_of(path: pathlib.Path) -> pathlib.Path:
    """Where `Rewrites` notes the renames it is making, beside the file it replaces last (an index)."""
    return path.with_name(f".{path.name}.rewrites")


def finish_rewrites(index: pathlib.Path) -> None:
    """Make the renames that a `Rewrites` stopped part-way through (a SIGKILL between them) noted
    beside `index`, if any; the caller holds the dataset (`editing`). A journal that is not one this
    package writes is refused whole (`journal_renames`), before anything is renamed."""
    journal = journal_of(index)
    renames = journal_renames(index)
    if renames is None:
        return
    for tmp, path in renames:
        if tmp.exists():  # renamed already otherwise
            os.replace(tmp, path)
    for directory in {path.parent for _, path in renames}:
        fsync_path(directory)
    journal.unlink()
    fsync_path(index.parent)


def journal_renames(index: pathlib.Path) -> list[tuple[pathlib.Path, pathlib.Path]] | None:
    """The renames (temporary file, file it replaces) noted beside `index` (None: no journal), each checked
    to be one a `Rewrites` of this dataset makes: both names inside the index's folder with no link on the
    way; the file is the index or a demo file in `episodes/`; the temporary one is that file's (`.<name>.
    <anything>.tmp` beside it) and a plain file. DatasetError naming the journal otherwise: a journal in a
    stranger's folder must not move their files (`["payload.sh", "/home/me/.bashrc"]`) or a folder in."""
    journal = journal_of(index)
    root = index.parent
    if not os.path.lexists(journal):  # a link there, even a dangling one, is refused below
        return None
    refused = f"{journal} (the renames of an interrupted edit)"
    try:
        require_plain_file(journal, "the edit journal")
        renames = json.loads(journal.read_text())
    except (OSError, ValueError, DatasetError) as e:
        raise DatasetError(f"{refused} cannot be read: {one_line(e)}; nothing was renamed; remove it if the "
                           "dataset reads as it should") from e
    shape = isinstance(renames, list) and all(
        isinstance(entry, list) and len(entry) == 2 and all(isinstance(n, str) for n in entry) for entry in renames)
    if not shape:
        shown = one_line(repr(renames))[:80]
        raise DatasetError(f"{refused} is not a list of [temporary name, file name] pairs ({shown}); nothing was "
                           "renamed; remove it if the dataset reads as it should")
    checked = []
    for tmp_name, name in renames:
        what = f"{journal.name}'s entry"
        try:
            path = inside(root, name, what, write=True)
            tmp = inside(root, tmp_name, what, write=True)
        except OutsideError as e:
            raise OutsideError(f"{refused}: {e}; nothing was renamed") from e
        ours = path == index or (path.parent == root / schema.EPISODES_DIR and _demo_file_name(path.name))
        if not ours or tmp.parent != path.parent or not tmp.name.startswith(f".{path.name}.") \
                or not tmp.name.endswith(".tmp"):
            raise OutsideError(f"{refused}: the entry [{tmp_name!r}, {name!r}] is not a rename an edit of this "
                               f"dataset makes (a `.{path.name}.*.tmp` beside {path.name}, {index.name} or "
                               f"{schema.EPISODES_DIR}/demo_<n>.hdf5); nothing was renamed")
        try:
            require_plain_file(tmp, "its temporary file")
            require_plain_file(path, "the file it replaces")
        except OutsideError as e:
            raise OutsideError(f"{refused}: {e}; nothing was renamed") from e
        checked.append((tmp, path))
    return checked


def _demo_file_name(name: str) -> bool:
    stem, dot, suffix = name.partition(".")
    try:
        schema.demo_index(stem)
    except ValueError:
        return False
    return dot == "." and suffix == "hdf5"


def _lock_file(lock: pathlib.Path, dataset: pathlib.Path) -> Any:
    """`lock` held exclusively. It is created if missing (never through a link: O_NOFOLLOW), and it must
    still be the file at that name once held: the holder before removed it on release, and a file
    no longer at the name locks nobody out."""
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as e:
            raise DatasetError(f"cannot lock {dataset} for editing ({lock}: {e.strerror})") from e
        fd = _held(fd, f"{dataset} is being edited by another tool (it holds {lock.name}); wait for it to finish")
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(lock, follow_symlinks=False))
        except FileNotFoundError:
            same = False
        if same:
            return fd
        unlock_directory(fd)


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
            require_no_link(path, "the dataset file")
            tmp = temporary(path)
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
