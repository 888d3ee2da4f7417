"""Files replaced whole: a new content is written beside, flushed, and renamed over the old, so a
crash at any instant leaves the old file or the new one (the bottom layer: datasets, checkpoints
and exports all write through it)."""

from __future__ import annotations

import contextlib
import os
import pathlib
from collections.abc import Iterator


def fsync_path(path: pathlib.Path) -> None:
    """Flush a file's (or directory's) data to the disk, so a rename after it is durable."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def replacing(path: pathlib.Path) -> Iterator[pathlib.Path]:
    """Yields a temporary path to write `path`'s new content to; when the block finishes, it is
    flushed to disk and renamed over `path` (and the directory flushed). If the block or the
    rename fails, the old `path` is untouched and the temporary file removed."""
    tmp = path.with_name(f".{path.name}.tmp")
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
