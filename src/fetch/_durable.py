"""Files replaced whole: a new content is written beside, flushed, and renamed over the old, so a
crash at any instant leaves the old file or the new one (the bottom layer: datasets, checkpoints
and exports all write through it)."""

from __future__ import annotations

import contextlib
import errno
import os
import pathlib
import tempfile
from collections.abc import Iterator

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
