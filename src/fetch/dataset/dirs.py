"""A directory written whole: built beside its target under a hidden name and renamed into place."""

from __future__ import annotations

import contextlib
import pathlib
import shutil
from collections.abc import Iterator

from fetch.errors import DatasetError
from fetch.teleop.stopping import raise_if_stopped


@contextlib.contextmanager
def replacing_dir(target: pathlib.Path, force: bool, what: str = "--out") -> Iterator[pathlib.Path]:
    """Yield an empty directory beside `target`; once the block ends without an error it becomes `target`.

    An existing non-empty `target` is an error unless `force`; then it is set aside and deleted only
    after the new one is in place. An error (or Ctrl-C) removes the new directory; a SIGKILL leaves
    it under its hidden name (`.<name>.partial`), which the next run removes, and `target` untouched.
    """
    target = pathlib.Path(target)
    if target.exists() and not target.is_dir():
        raise DatasetError(f"{what} {target} is a file; give a directory")
    if target.is_dir() and any(target.iterdir()) and not force:
        raise DatasetError(f"{what} {target} already exists and is not empty; choose another, or pass --force to "
                           "replace it")
    building = target.with_name(f".{target.name}.partial")
    aside = target.with_name(f".{target.name}.replaced")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.rmtree(building, ignore_errors=True)  # what a killed run left
        building.mkdir()
    except OSError as e:
        raise DatasetError(f"cannot create {building}: {e}") from e
    try:
        yield building
        # A Ctrl-C or SIGTERM whose exception Python swallowed (raised while a weakref callback or
        # __del__ ran: "Exception ignored in ...") still stops the run here, before anything is replaced.
        raise_if_stopped()
        shutil.rmtree(aside, ignore_errors=True)
        if target.exists():
            target.rename(aside)
        try:
            building.rename(target)
        except BaseException:
            if aside.exists():
                aside.rename(target)
            raise
    except BaseException:
        shutil.rmtree(building, ignore_errors=True)
        raise
    shutil.rmtree(aside, ignore_errors=True)
