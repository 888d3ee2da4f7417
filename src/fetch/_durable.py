"""Files that survive a kill at any instant: one replaced whole (written beside, flushed, renamed over the
old, the directory flushed), several replaced together (`Rewrites`), a directory or file held by one
process at a time. The bottom layer: datasets, checkpoints and exports all write through it."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import pathlib
import shutil
import tempfile
from collections.abc import Callable, Iterator
from typing import Any

import h5py

from fetch._confine import inside, require_no_link, require_plain_file
from fetch.errors import DatasetError, OutsideError, one_line

NO_ROOM = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""The errors of a write that found no room: a full disk, a quota, a file-size limit."""


def why(e: OSError) -> str:
    """What went wrong with a file, in a few words on one line ("the disk is full"); HDF5's own
    messages span several lines."""
    known = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is exceeded",
             errno.EFBIG: "the file-size limit was reached", errno.EACCES: "permission denied",
             errno.EROFS: "the file system is read-only"}
    return known.get(e.errno or 0) or " ".join(str(e).split())


def fsync_path(path: pathlib.Path) -> None:
    """Flush a file's (or directory's) data to the disk, so a rename after it is durable."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def temporary(path: pathlib.Path) -> pathlib.Path:
    """A new empty file beside `path`, `.<name>.<random>.tmp`, created here and now (O_EXCL, no link
    followed): never a name that was already there, so a link a stranger planted in the folder (at
    `.demos.hdf5.tmp`, say) is never written through."""
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    return pathlib.Path(name)


@contextlib.contextmanager
def replacing(path: pathlib.Path) -> Iterator[pathlib.Path]:
    """Yields a temporary path (`temporary`) to write `path`'s new content to; when the block finishes,
    it is flushed to disk and renamed over `path` (and the directory flushed). If the block or the
    rename fails, the old `path` is untouched and the temporary file removed. A link at `path` is
    replaced by the file, never written through."""
    tmp = temporary(path)
    try:
        yield tmp
        fsync_path(tmp)
        os.replace(tmp, path)
        fsync_path(path.parent)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def atomic_write(path: pathlib.Path, content: bytes) -> None:
    """Replace `path` with `content` all at once (see `replacing`)."""
    with replacing(path) as tmp:
        tmp.write_bytes(content)


# -- a directory or file held by one process at a time -----------------------------------------------

class BusyError(DatasetError):
    """Another collector or tool holds the directory or file."""


def lock_directory(directory: pathlib.Path, alternative: str) -> Any:
    """Hold `directory` itself exclusively (an flock on the directory, until `unlock_directory`);
    BusyError if another collector or tool holds it. `alternative` completes the message
    ("choose another --out"). A lock on a file inside could be bypassed by deleting the file."""
    return _held(os.open(directory, os.O_RDONLY | os.O_DIRECTORY),
                 f"{directory} is in use by another collector or tool (it holds the directory's lock); wait for "
                 f"it to finish or {alternative}")


def _held(fd: int, refusal: str) -> int:
    """`fd`, locked exclusively; BusyError(`refusal`) (and `fd` closed) if another process holds it."""
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


def lock_file(lock: pathlib.Path, held: pathlib.Path) -> Any:
    """`lock` held exclusively, for `held` (the file it guards; released with `unlock_directory`). It is
    created if missing (never through a link: O_NOFOLLOW), and it must still be the file at that name once
    held: the holder before removed it on release, and a file no longer at the name locks nobody out."""
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as e:
            raise DatasetError(f"cannot lock {held} for editing ({lock}: {e.strerror})") from e
        fd = _held(fd, f"{held} is being edited by another tool (it holds {lock.name}); wait for it to finish")
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(lock, follow_symlinks=False))
        except FileNotFoundError:
            same = False
        if same:
            return fd
        unlock_directory(fd)


# -- several files replaced together ---------------------------------------------------------------

def journal_of(path: pathlib.Path) -> pathlib.Path:
    """Where `Rewrites` notes the renames it is making, beside the file it replaces last (an index)."""
    return path.with_name(f".{path.name}.rewrites")


def journal_renames(last: pathlib.Path, ours: Callable[[pathlib.Path], bool],
                    described: str) -> list[tuple[pathlib.Path, pathlib.Path]] | None:
    """The renames (temporary file, file it replaces) noted beside `last` (None: no journal), each checked
    to be one a `Rewrites` of these files makes: both names inside `last`'s folder with no link on the way;
    the file one that `ours` accepts (`described` says which, for the message); the temporary one that
    file's (`.<name>.<anything>.tmp` beside it) and a plain file. DatasetError naming the journal otherwise:
    a journal in a stranger's folder must not move their files (`["payload.sh", "/home/me/.bashrc"]`) or a
    folder in."""
    journal = journal_of(last)
    root = last.parent
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
        if not ours(path) or tmp.parent != path.parent or not tmp.name.startswith(f".{path.name}.") \
                or not tmp.name.endswith(".tmp"):
            raise OutsideError(f"{refused}: the entry [{tmp_name!r}, {name!r}] is not a rename an edit of this "
                               f"dataset makes (a `.{path.name}.*.tmp` beside {path.name}, {described}); nothing "
                               "was renamed")
        try:
            require_plain_file(tmp, "its temporary file")
            require_plain_file(path, "the file it replaces")
        except OutsideError as e:
            raise OutsideError(f"{refused}: {e}; nothing was renamed") from e
        checked.append((tmp, path))
    return checked


def finish_renames(last: pathlib.Path, ours: Callable[[pathlib.Path], bool], described: str) -> None:
    """Make the renames that a `Rewrites` stopped part-way through (a SIGKILL between them) noted beside
    `last`, if any; the caller holds the files. A journal that is not one a `Rewrites` of `ours` files
    writes is refused whole (`journal_renames`), before anything is renamed."""
    journal = journal_of(last)
    renames = journal_renames(last, ours, described)
    if renames is None:
        return
    for tmp, path in renames:
        if tmp.exists():  # renamed already otherwise
            os.replace(tmp, path)
    for directory in {path.parent for _, path in renames}:
        fsync_path(directory)
    journal.unlink()
    fsync_path(last.parent)


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
                # the files (`finish_renames`), not left half old, half new (some demos with images
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
