"""A run's checkpoint: tensors and plain containers only (`torch.load(weights_only=True)`), written atomically."""

from __future__ import annotations

import json
import os
import pathlib
from typing import Any

from fetch.errors import FetchError

FORMAT = "gym-fetch-v2/policy"
VERSION = 1
NAME = "checkpoint.pt"
KEYS = ("format", "version", "policy", "train", "source", "step", "norm", "seeds", "model", "optimizer", "rng",
        "history")
"""What every checkpoint holds; one may also hold `horizon` (the episode length its policy is given, [steps];
a checkpoint without it is given its task's registered horizon)."""


def path(run: str | os.PathLike[str]) -> pathlib.Path:
    return pathlib.Path(run) / NAME


def write(run: pathlib.Path, content: bytes) -> None:
    """Replace the checkpoint all at once: a temporary file, flushed to disk, renamed over the old one.
    A kill at any moment leaves the previous checkpoint or the new one, never a torn file."""
    from fetch._durable import atomic_write

    try:
        atomic_write(path(run), content)
    except OSError as e:
        raise FetchError(f"cannot write the checkpoint {path(run)}: {e}") from e


def read(run: str | os.PathLike[str]) -> dict[str, Any]:
    """The checkpoint of `run` (a run directory or the checkpoint file), checked to be ours."""
    import torch

    p = pathlib.Path(run)
    if dataset_at(p):
        raise FetchError(f"{p} is a dataset, not a run: train a policy on it with `gym-fetch train {p} --out "
                         "runs/NAME`, then `gym-fetch eval runs/NAME`")
    file = p if p.is_file() else path(p)
    if not file.exists():
        what = "is not a run directory" if p.exists() else "does not exist"
        raise FetchError(f"{p} {what}: no {NAME} (make one with `gym-fetch train DATASET --out {p}`)")
    try:
        state = torch.load(file, weights_only=True, map_location="cpu")
    except Exception as e:  # torch raises RuntimeError, UnpicklingError, EOFError, ... on a bad file
        raise FetchError(f"{file} is not a readable policy checkpoint: {' '.join(str(e).split())[:200]}") from e
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise FetchError(f"{file} is not a gym-fetch-v2 policy checkpoint (format {FORMAT!r})")
    if state.get("version") != VERSION or set(KEYS) - set(state):
        raise FetchError(f"{file}: checkpoint version {state.get('version')!r} or its keys are not what this "
                         f"version of gym-fetch-v2 reads (version {VERSION}: {', '.join(KEYS)})")
    return state


def dataset_at(p: pathlib.Path) -> bool:
    """Whether `p` is a dataset: a collector's directory (it holds the index) or an HDF5 file."""
    from fetch.dataset.schema import INDEX_NAME

    if p.is_dir():
        return (p / INDEX_NAME).is_file()
    try:
        with open(p, "rb") as f:
            return f.read(8) == b"\x89HDF\r\n\x1a\n"
    except OSError:
        return False


def require_outside(run: pathlib.Path, dataset: pathlib.Path) -> None:
    """FetchError unless the run directory `run` is outside the dataset whose file is `dataset` (a
    collector's directory, when that file is its index; else the file itself)."""
    from fetch.dataset.schema import INDEX_NAME

    root = dataset.resolve().parent if dataset.name == INDEX_NAME else dataset.resolve()
    out = run.resolve()
    if out == root or root in out.parents:
        raise FetchError(f"--out {run} is inside the dataset {root}: a run writes its checkpoints there; choose a "
                         "folder outside it, e.g. --out runs/NAME")


def require_same(run: pathlib.Path, previous: dict[str, Any], policy: dict[str, Any], train: dict[str, Any],
                 source: dict[str, Any]) -> None:
    """A resumed run must be the same run: same policy, training settings and data."""
    for what, old, new in (("policy", previous["policy"], policy), ("training", previous["train"], train),
                           ("data", previous["source"], source)):
        if plain(old) != plain(new):
            changed = sorted(k for k in set(old) | set(new) if plain(old.get(k)) != plain(new.get(k)))
            raise FetchError(f"{run} holds a run with other {what} settings ({', '.join(changed)} differ); "
                             "resume it with the same arguments, or train into another --out")


def plain(value: Any) -> Any:
    """`value` as JSON would give it back (tuples as lists, ...): how two sets of settings are compared."""
    return json.loads(json.dumps(value, sort_keys=True))
