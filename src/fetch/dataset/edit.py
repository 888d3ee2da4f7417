"""`gym-fetch merge` and `gym-fetch split`: combine datasets of one env, remake the train/valid split.

`merge` writes one self-contained file (every demo inside it, no links), the form to copy around
and hand to training code. `split` rewrites only `mask/train` and `mask/valid`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import pathlib
import time
from typing import Any

import h5py
import numpy as np

from fetch._durable import NO_ROOM, replacing, rewritten, why
from fetch._progress import progress
from fetch.dataset import schema
from fetch.dataset.dirs import require_apart
from fetch.dataset.holding import editing
from fetch.dataset.reader import Dataset, open_dataset, resolve
from fetch.dataset.validation import require_valid
from fetch.dataset.writer import package_versions
from fetch.errors import DatasetError, FetchError
from fetch.stopping import raise_if_stopped

SAME = ("env_id", "env_kwargs", "layout", "model_hash")
"""What datasets must share to be merged: the task, the arrays, and the model the states belong to."""


def write_masks(f: h5py.File, masks: dict[str, list[str]]) -> None:
    """Replace the file's `mask` group: one dataset of demo names per key (the three splits always)."""
    if "mask" in f:
        del f["mask"]
    group = f.create_group("mask")
    for key in (*schema.SPLITS, *sorted(k for k in masks if k not in schema.SPLITS)):
        names = masks.get(key, [])
        group.create_dataset(key, data=np.array(names, dtype="S"), shape=(len(names),),
                             dtype=f"S{max((len(n) for n in names), default=1)}")


def _split_of(ds: Dataset) -> dict[str, str]:
    masks = ds.masks()
    return {name: key for key in schema.SPLITS for name in masks.get(key, [])}


# -- merge ------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class MergeReport:
    out: pathlib.Path
    demos: int
    steps: int
    masks: dict[str, int]


def _out_path(out: str | os.PathLike[str], inputs: list[pathlib.Path], force: bool) -> pathlib.Path:
    p = pathlib.Path(out)
    if p.is_dir() or str(out).endswith(os.sep):
        raise FetchError(f"--out {out} is a directory; merge writes one file: give a file name such as "
                         f"{p / 'merged.hdf5'}")
    if p.suffix.lower() not in (".hdf5", ".h5"):
        raise FetchError(f"--out {out}: name the merged file .hdf5 (or .h5)")
    if not p.parent.is_dir():
        raise FetchError(f"--out {out}: the directory {p.parent} does not exist")
    require_apart(p, inputs)
    if p.exists() and not force:
        raise FetchError(f"{p} exists; pass --force to replace it")
    return p


def merge(inputs: list[str | os.PathLike[str]], out: str | os.PathLike[str], force: bool = False) -> MergeReport:
    """Write the demos of `inputs` (in order) to one new file, renumbered `demo_0...`; each keeps its
    split (train, valid or failed) and names its origin in the attribute `source`."""
    if len(inputs) < 2:
        raise FetchError(f"merge needs at least two datasets, got {len(inputs)}")
    with contextlib.ExitStack() as stack:
        sources = [stack.enter_context(open_dataset(p)) for p in inputs]
        seen: dict[pathlib.Path, str] = {}
        for given, source in zip(inputs, sources, strict=True):
            key = source.path.resolve()
            if key in seen:
                raise FetchError(f"{given} and {seen[key]} are the same dataset ({key}); merging it with itself "
                                 "would duplicate every demo")
            seen[key] = str(given)
        for source in sources:  # nothing a tool flags as invalid is passed on
            require_valid(source)
        target = _out_path(out, [s.path for s in sources], force)
        first = sources[0]
        hashes = [str(s.data_attrs["model_hash"]) for s in sources]
        if len(set(hashes)) > 1:  # maybe some are stamped the old way: compare in today's form
            hashes = [_current_hash(s) for s in sources]
        for other, other_hash in zip(sources[1:], hashes[1:], strict=True):
            mine, theirs = first.header_attrs(), other.header_attrs()
            mine["model_hash"], theirs["model_hash"] = hashes[0], other_hash
            differences = [f"{key}: {first.path} has {mine[key]!r}, {other.path} has {theirs[key]!r}"
                           for key in SAME if mine[key] != theirs[key]]
            if differences:
                raise DatasetError("these datasets cannot be merged (demos of different tasks, arrays or models "
                                   "would be mixed):\n  " + "\n  ".join(differences))
        total = sum(len(s.demo_names) for s in sources)
        try:
            with replacing(target) as tmp, h5py.File(tmp, "w") as f:
                report = _write_merged(f, sources, total, target, hashes[0])
                raise_if_stopped()  # a stop whose exception Python swallowed: nothing is written
        except OSError as e:
            if e.errno not in NO_ROOM:
                raise
            raise DatasetError(f"could not write {target}: {why(e)}; nothing was written") from e
    return report


def _current_hash(ds: Dataset) -> str:
    """The dataset's model hash, in today's install-independent form if it holds this install's old-style
    hash of the same model (datasets recorded before `FetchEnv.model_hash` left the install paths out)."""
    import gymnasium as gym

    recorded = str(ds.data_attrs["model_hash"])
    env = gym.make(ds.env_id, **ds.env_kwargs)
    try:
        base: Any = env.unwrapped
        return str(base.model_hash()) if recorded == base.legacy_model_hash() else recorded
    finally:
        env.close()


def _write_merged(f: h5py.File, sources: list[Dataset], total: int, target: pathlib.Path,
                  model_hash: str) -> MergeReport:
    first = sources[0]
    settings = dict(first.settings)
    for s in sources[1:]:  # keep the settings all inputs share; the differing ones go to `sources`
        settings = {k: v for k, v in settings.items() if s.settings.get(k) == v}
    data = f.create_group("data")
    names: list[tuple[Dataset, str]] = [(s, name) for s in sources for name in s.demo_names]
    masks: dict[str, list[str]] = {}
    steps = 0
    splits = {id(s): _split_of(s) for s in sources}
    extra = {id(s): {k: set(v) for k, v in s.masks().items() if k not in schema.SPLITS} for s in sources}
    for index, (source, name) in enumerate(progress(names, total, "merge")):
        new = schema.demo_name(index)
        group = source.demo(name)
        f.copy(group, data, name=new)
        data[new].attrs["source"] = f"{source.path}:{name}"
        steps += int(group.attrs["num_samples"])
        split = splits[id(source)].get(name)
        if split is None:
            raise DatasetError(f"{source.path}: {name} is in none of mask/train, mask/valid, mask/failed "
                               "(`gym-fetch info` lists the problems)")
        masks.setdefault(split, []).append(new)
        for key, listed in extra[id(source)].items():
            if name in listed:
                masks.setdefault(key, []).append(new)
    attrs: dict[str, Any] = {
        "total": steps,
        "env_args": json.dumps({"env_name": first.env_id, "type": schema.ENV_TYPE_GYM,
                                "env_kwargs": first.env_kwargs}),
        "format": schema.FORMAT,
        "format_version": schema.FORMAT_VERSION,
        "versions": json.dumps(package_versions()),
        "created": time.time(),
        "settings": json.dumps(settings, sort_keys=True),
        "layout": first.data_attrs["layout"],
        "model_xml": first.data_attrs["model_xml"],
        "model_hash": model_hash,
        "attempts": sum(int(s.data_attrs.get("attempts", 0)) for s in sources),
        "sources": json.dumps([{"path": str(s.path), "demos": len(s.demo_names), "settings": s.settings,
                                "versions": s.versions, "created": s.data_attrs.get("created")} for s in sources]),
    }
    for key, value in attrs.items():
        data.attrs[key] = value
    write_masks(f, masks)
    return MergeReport(target, total, steps, {k: len(v) for k, v in masks.items()})


# -- split ------------------------------------------------------------------------------------------

def split(path: str | os.PathLike[str], valid: float, seed: int = 0) -> dict[str, int]:
    """Reassign the successful demos to `mask/train` and `mask/valid`: a `valid` fraction (rounded,
    at least one when there are two or more demos and `valid` > 0), drawn with `seed`. Failed
    demos stay in `mask/failed`; other filter keys are kept. Returns the new mask sizes."""
    if not 0.0 <= valid < 1.0:
        raise FetchError(f"--valid must be a fraction in [0, 1), got {valid}")
    if not 0 <= seed < 2**63:
        raise FetchError(f"--seed must be a whole number from 0 to 2**63 - 1, got {seed}")
    index = resolve(path)
    with editing(index):
        with open_dataset(index) as ds:
            require_valid(ds)
            masks = ds.masks()
            successful = [n for n in ds.demo_names if bool(ds.demo(n).attrs["success"])]
            failed = [n for n in ds.demo_names if n not in set(successful)]
        count = int(round(valid * len(successful)))
        if valid > 0 and len(successful) >= 2:
            count = min(max(count, 1), len(successful) - 1)
        chosen = set(np.random.default_rng(seed).permutation(len(successful))[:count].tolist())
        masks["valid"] = [n for i, n in enumerate(successful) if i in chosen]
        masks["train"] = [n for i, n in enumerate(successful) if i not in chosen]
        masks["failed"] = failed
        try:
            with rewritten(index) as f:
                write_masks(f, masks)
                f["data"].attrs["split"] = json.dumps({"valid": valid, "seed": seed})
                raise_if_stopped()  # a stop whose exception Python swallowed: the index stays as it was
        except OSError as e:
            if e.errno not in NO_ROOM:
                raise
            raise DatasetError(f"could not rewrite {index}: {why(e)}; it is unchanged") from e
    return {k: len(masks[k]) for k in schema.SPLITS}
