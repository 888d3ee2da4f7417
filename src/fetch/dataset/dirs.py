"""A directory written whole: built beside its target under a hidden name and renamed into place; the
rule that an output never lies on an input; a directory named by an environment variable."""

from __future__ import annotations

import contextlib
import os
import pathlib
import shutil
from collections.abc import Iterable, Iterator

from fetch.errors import DatasetError, FetchError
from fetch.stopping import raise_if_stopped


@contextlib.contextmanager
def replacing_dir(target: pathlib.Path, force: bool, what: str = "--out") -> Iterator[pathlib.Path]:
    """Yield an empty directory beside `target`; once the block ends without an error it becomes `target`.

    An existing non-empty `target` is an error unless `force`; then it is set aside and deleted only
    after the new one is in place. An error (or Ctrl-C) removes the new directory; a SIGKILL leaves
    it under its hidden name (`.<name>.partial`), which the next run removes, and `target` untouched
    (or, killed between the two renames, set aside: `recover_replaced` puts it back first).
    """
    given, target = target, pathlib.Path(target).resolve()
    here = pathlib.Path.cwd().resolve()
    if target == here or target in here.parents:
        raise DatasetError(f"{what} {given} is the directory you are in, or holds it; it cannot be replaced "
                           f"while in use: give a new directory, e.g. {what} report")
    recover_replaced(target)
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


def recover_replaced(target: pathlib.Path) -> None:
    """Put back what a replacement killed between its two renames set aside (`.<name>.replaced`, with no
    `target`): the old directory, whole; an aside left beside a `target` in place is deleted."""
    aside = target.with_name(f".{target.name}.replaced")
    if aside.is_dir() and not target.exists():
        aside.rename(target)
    else:
        shutil.rmtree(aside, ignore_errors=True)


def dataset_extent(path: str | os.PathLike[str]) -> pathlib.Path:
    """What a dataset argument covers on disk, resolved: a collector's directory (given as the directory
    or as its index file, whose demo files live beside it), else the file itself (a merged file)."""
    from fetch.dataset.schema import INDEX_NAME

    p = pathlib.Path(path).resolve()
    return p.parent if p.name == INDEX_NAME and p.is_file() else p


def require_apart(out: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str]], what: str = "--out",
                  remedy: str = "write it elsewhere, outside the input") -> None:
    """DatasetError unless `out` is neither an input, nor inside one, nor a directory that holds one:
    writing there, or replacing it with --force, would overwrite or delete what the tool reads. The
    error names `what` was given and ends with `remedy`."""
    target = pathlib.Path(out).resolve()
    for given in inputs:
        source = dataset_extent(given)
        if target == source or source in target.parents:
            where = "is" if target == source else "is inside"
            raise DatasetError(f"{what} {out} {where} the input {source}; {remedy}")
        if target in source.parents:
            raise DatasetError(f"{what} {out} holds the input {source}; {remedy}")


def env_dir(name: str, default: str) -> pathlib.Path | None:
    """The directory $`name` names, as given, None where it is unset. Set but empty it is refused
    with one line: Minari, LeRobot and the Hub take an empty value as the current directory, which is
    never where a dataset is meant to go, and reading it as unset would write where they do not look."""
    value = os.environ.get(name)
    if value is None:
        return None
    if not value.strip():
        raise FetchError(f"{name} is set but empty; unset it (for the default, {default}) or set it to a directory")
    return pathlib.Path(value)
