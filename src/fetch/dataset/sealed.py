"""HDF5 content that reads nothing but its own file: the one check every reader of a dataset makes.

HDF5 can make a file read other files: an external link (`h5py.ExternalLink`, a group or dataset in
another file), a dataset with external storage (its bytes kept in any raw file, `/home/me/secret.bin`
say) and a virtual dataset (its rows taken from datasets in other files). Read through, a stranger's
dataset would copy a local file into every export (`export --to npz` its bytes, `merge` the
reference). The only such link a dataset of ours has is a collector's index linking each demo to its
file in `episodes/` (`Dataset.demo` checks where that leads); everything else of the kind is refused,
and so are soft links, which this package never writes (one could lead a demo's read into another
demo that was not checked).

The checks run on HDF5's own iteration (`H5Lvisit`, `H5Ovisit`), under 0.1 ms per dataset: a demo
when it is first read, the rest of an index when it is opened.
"""

from __future__ import annotations

import math
import os
from typing import Any

import h5py
from h5py import h5d, h5l, h5o

from fetch.errors import DatasetError, OutsideError
from fetch.tasks import MAX_STEPS

MAX_ROWS = MAX_STEPS + 1
"""The most rows an array of a demo has: one per step, and the start state (`fetch.tasks.MAX_STEPS`)."""
EXPANSION = 200
"""How many times its file's size a demo's arrays may take once read. Rendered images and physics states
compress a few times over; an array of zeros declared at terabytes compresses to kilobytes (a compression
bomb): that is not what the data's own size explains."""
FLOOR = 256 * 2**20
"""[bytes] What a demo's arrays may always take, whatever its file's size."""


def check_sealed(group: h5py.Group, where: str) -> None:
    """OutsideError naming `where` (the file, the demo) and the member if anything below `group` reads
    another file (an external link, a dataset with external storage, a virtual dataset) or is a soft link;
    DatasetError if an array has more rows than a demo can (`MAX_ROWS`) or the arrays would take more memory
    than their file's size explains (`EXPANSION`), before any is read."""
    sizes: list[tuple[str, int, int]] = []
    problem = _links(group.id) or _datasets(group.id, sizes=sizes)
    if problem:
        _refuse(where, problem)
    for name, rows, _ in sizes:
        if rows > MAX_ROWS:
            raise DatasetError(f"{where}: {name} has {rows} rows, more than a demo has ({MAX_ROWS}: a state per step "
                               "and the start); refused before reading")
    total, file_bytes = sum(n for _, _, n in sizes), os.path.getsize(group.file.filename)
    if total > max(FLOOR, EXPANSION * file_bytes):
        raise DatasetError(f"{where}: its arrays would take {total / 2**30:.1f} GiB once read, from a file of "
                           f"{file_bytes / 2**20:.1f} MiB (over {EXPANSION} times its size); refused before reading")


def check_index(file: h5py.File, where: str, demos: str = "data") -> None:
    """`check_sealed` for an index, but for the demos in `demos` (the group whose members are demos): those
    are checked where they are read (`Dataset.demo`), so a tool that reads a few demos of a large merged file
    pays for those few. External links directly in `demos` (a collector's links to its demo files) are let
    through, to be checked where they are followed."""
    problems: list[str | None] = []
    # The members are listed first, then checked: a visit started inside another's callback lets an HDF5
    # error (a corrupt heap) escape h5py's lock as a SystemError.
    for name, kind in _members(file.id):
        if kind == h5l.TYPE_SOFT:
            problems.append(f"{name} is a soft link")
        elif kind != h5l.TYPE_HARD:
            problems.append(f"{name} is an external link")
        elif name != demos:
            member = h5o.open(file.id, name.encode())
            problems.append(_links(member, name) or _datasets(member, name))
    data = file.get(demos)
    if isinstance(data, h5py.Group):
        for name, kind in _members(data.id):
            if kind == h5l.TYPE_SOFT:
                problems.append(f"{demos}/{name} is a soft link")
            elif kind == h5l.TYPE_HARD:
                member = h5o.open(data.id, name.encode())
                if isinstance(member, h5d.DatasetID):  # not a demo: say why if it reads another file
                    problems.append(_dataset(member, f"{demos}/{name}"))
    first = next((p for p in problems if p), None)
    if first:
        _refuse(where, first)


def _members(gid: Any) -> list[tuple[str, int]]:
    """(name, link type) of each link directly in the group `gid`."""
    found: list[tuple[str, int]] = []
    gid.links.iterate(lambda name, info: found.append((name.decode(errors="replace"), info.type)), info=True)
    return found


def _refuse(where: str, problem: str) -> None:
    raise OutsideError(f"{where}: {problem}; a dataset's arrays must be stored in its own files, so it is refused "
                       "(nothing outside its folder is read)")


def _links(gid: Any, prefix: str = "") -> str | None:
    """The first link below the group `gid` that is external or soft, said in words; None if there is none."""
    found: list[str] = []

    def visit(name: bytes, info: Any) -> int | None:
        if info.type == h5l.TYPE_HARD:
            return None
        text = _joined(prefix, name)
        if info.type == h5l.TYPE_SOFT:
            found.append(f"{text} is a soft link")
        else:
            found.append(f"{text} is an external link to another file")
        return 1  # stop: one is enough

    if isinstance(gid, h5d.DatasetID):
        return None
    gid.links.visit(visit, info=True)
    return found[0] if found else None


def _datasets(oid: Any, prefix: str = "", sizes: list[tuple[str, int, int]] | None = None) -> str | None:
    """The first dataset at or below `oid` whose data lies in other files, said in words; None if there is none.
    Each dataset's (name, rows, size in memory [bytes]) is appended to `sizes`."""
    if isinstance(oid, h5d.DatasetID):
        return _dataset(oid, prefix, sizes)
    found: list[str] = []

    def visit(name: bytes, info: Any) -> int | None:
        if info.type != h5o.TYPE_DATASET or name == b".":
            return None
        problem = _dataset(h5d.open(oid, name), _joined(prefix, name), sizes)
        if problem:
            found.append(problem)
            return 1
        return None

    h5o.visit(oid, visit, info=True)
    return found[0] if found else None


def _dataset(did: Any, name: str, sizes: list[tuple[str, int, int]] | None = None) -> str | None:
    if sizes is not None:
        shape = did.shape
        sizes.append((name, shape[0] if shape else 1, did.get_type().get_size() * math.prod(shape)))
    plist = did.get_create_plist()
    if plist.get_layout() == h5d.VIRTUAL:
        return f"{name} is a virtual dataset (its rows come from other files)"
    count = plist.get_external_count()
    if count:
        files = sorted({plist.get_external(i)[0].decode(errors="replace") for i in range(count)})
        return f"{name} keeps its data in another file ({', '.join(files)})"
    return None


def _joined(prefix: str, name: bytes) -> str:
    text = name.decode(errors="replace")
    return f"{prefix}/{text}" if prefix else text
