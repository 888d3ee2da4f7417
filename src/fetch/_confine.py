"""Names taken from a folder's own contents (a dataset's demo links and edit journal, a run's checkpoint)
resolved inside that folder, or refused.

A dataset or run folder may come from a stranger: its files are data. Whatever path such a file names
is resolved here, and nowhere else, so one rule holds for every tool (docs/security.md): a name that is
absolute, climbs out with `..`, or reaches outside through a symbolic link is refused; where a tool
writes, no symbolic link is followed at all, not even one that stays inside. The folder itself, the
path a user gave on the command line, is the user's choice and is taken as it is.
"""

from __future__ import annotations

import os
import pathlib
import stat

from fetch.errors import OutsideError


def inside(root: pathlib.Path, name: str | os.PathLike[str], what: str, *, write: bool = False) -> pathlib.Path:
    """`root / name`, where `name` was read from the folder `root` (a link's file name, a journal's
    entry); `what` says where it was read ("demo_1's link"), for the message.

    OutsideError when `name` is empty, absolute or has a `..` part, or when its real location (symbolic
    links followed) leaves `root`; with `write`, also when any part below `root` is a symbolic link."""
    text = os.fspath(name)
    parts = pathlib.PurePosixPath(text).parts
    if not text or "\x00" in text or text.startswith("/") or ".." in parts or "\\" in text:
        raise OutsideError(f"{what} names {text!r}, which is not a plain name inside {root}: a folder's files may "
                           "only name files inside it (no absolute path, no '..')")
    path = root.joinpath(*parts)
    if write:
        walked = root
        for part in parts:
            walked = walked / part
            if walked.is_symlink():
                raise OutsideError(f"{walked} is a symbolic link (to {_target(walked)}); a tool never writes "
                                   f"through a link in a folder it edits: replace the link with the file")
    home = root.resolve()
    real = path.resolve()
    if real != home and home not in real.parents:
        raise OutsideError(f"{what} names {text!r}, which leads to {real}, outside {home}; a folder's files may "
                           "only name files inside it")
    return path


def require_plain_file(path: pathlib.Path, what: str) -> None:
    """OutsideError unless `path` is a regular file of one name (not a link of either kind, a folder or a
    FIFO): what a tool renames into place or deletes as its own must be a file it wrote."""
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISLNK(info.st_mode):
        raise OutsideError(f"{what} {path} is a symbolic link (to {_target(path)}), not a file this package wrote")
    if not stat.S_ISREG(info.st_mode):
        raise OutsideError(f"{what} {path} is not a regular file, so it is not one this package wrote")
    if info.st_nlink > 1:
        raise OutsideError(f"{what} {path} has {info.st_nlink} hard links, so it is also a file elsewhere; a file "
                           "this package wrote has one")


def require_no_link(path: pathlib.Path, what: str) -> None:
    """OutsideError if `path` itself is a symbolic link: a file or folder a tool writes into, named by
    the tool, not by the user (a dataset's `episodes/`, a run's checkpoint)."""
    if path.is_symlink():
        raise OutsideError(f"{what} {path} is a symbolic link (to {_target(path)}); a tool never writes through "
                           "a link in a folder it edits: replace the link with what it points to")


def _target(link: pathlib.Path) -> str:
    try:
        return os.readlink(link)
    except OSError:
        return "?"
