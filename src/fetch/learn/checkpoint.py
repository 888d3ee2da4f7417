"""A run's checkpoint: tensors and plain containers only (`torch.load(weights_only=True)`), written atomically."""

from __future__ import annotations

import json
import os
import pathlib
import pickle
import re
import reprlib
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
    from fetch._confine import require_no_link
    from fetch._durable import atomic_write

    require_no_link(path(run), "the run's checkpoint")  # a stranger's run folder: replaced, never written through
    try:
        atomic_write(path(run), content)
    except OSError as e:
        raise FetchError(f"cannot write the checkpoint {path(run)}: {e}") from e


def file_of(run: str | os.PathLike[str]) -> pathlib.Path:
    """The checkpoint file of `run`: a run directory's `NAME` (inside it: a link out of a stranger's run
    folder is refused, `fetch._confine`), or the file given."""
    from fetch._confine import inside

    p = pathlib.Path(run)
    if p.is_dir():
        return inside(p, NAME, f"{p}: the run's checkpoint")
    return p


def read(run: str | os.PathLike[str]) -> dict[str, Any]:
    """The checkpoint of `run` (a run directory or the checkpoint file), checked to be ours and every field
    in it checked before use (`fetch.learn.checked.check`): a checkpoint may come from a stranger."""
    import torch

    from fetch.learn.checked import check

    p = pathlib.Path(run)
    if dataset_at(p):
        raise FetchError(f"{p} is a dataset, not a run: train a policy on it with `gym-fetch train {p} --out "
                         "runs/NAME`, then `gym-fetch eval runs/NAME`")
    file = file_of(p)
    if not file.exists():
        what = "is not a run directory" if p.exists() else "does not exist"
        raise FetchError(f"{p} {what}: no {NAME} (make one with `gym-fetch train DATASET --out {p}`)")
    if not file.is_file():  # a FIFO would block the read for ever
        raise FetchError(f"{file} is not a regular file, so not a policy checkpoint")
    try:
        state = torch.load(file, weights_only=True, map_location="cpu")
    except pickle.UnpicklingError as e:  # what weights_only refuses: a pickled object, or not a pickle at all
        raise FetchError(unpickled(file, e)) from e
    except Exception as e:  # torch raises RuntimeError, EOFError, OSError, ... on a damaged file
        raise FetchError(f"{file} is not a readable policy checkpoint: {first_sentence(e)}") from e
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise FetchError(f"{file} is not a gym-fetch-v2 policy checkpoint (format {FORMAT!r})")
    if state.get("version") != VERSION or set(KEYS) - set(state):
        raise FetchError(f"{file}: checkpoint version {reprlib.repr(state.get('version'))} or its keys are not what "
                         f"this version of gym-fetch-v2 reads (version {VERSION}: {', '.join(KEYS)})")
    check(file, state)
    return state


def unpickled(file: pathlib.Path, e: pickle.UnpicklingError) -> str:
    """Why `torch.load(file, weights_only=True)` refused `file`, in one line."""
    text = " ".join(str(e).split())
    found = re.search(r"Unsupported global: GLOBAL (\S+)", text)
    if found:
        return (f"{file} is not a weights-only checkpoint: it holds pickled Python objects ({found[1]} among them), "
                "which can run code when loaded, so it is refused (a run's checkpoint holds tensors and plain values "
                "only)")
    detail = text.partition("WeightsUnpickler error:")[2].partition(" Check the documentation")[0].strip()
    return (f"{file} is not a readable policy checkpoint: not a weights-only file ({detail or type(e).__name__}); "
            "other pickles are refused, since loading one can run code")


def first_sentence(e: BaseException) -> str:
    """The first sentence of an error's message, on one line (torch's go on with advice for its own users)."""
    text = " ".join(str(e).split())
    return text.split(". ")[0] if text else type(e).__name__


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


ACTING_ONLY = ("act_steps",)
"""Policy settings that change how the trained network acts, not what it learns: a run interrupted before their
default changed resumes (and acts as a new run does)."""


def require_same(run: pathlib.Path, previous: dict[str, Any], policy: dict[str, Any], train: dict[str, Any],
                 source: dict[str, Any]) -> None:
    """A resumed run must be the same run: same policy (but for `ACTING_ONLY`), training settings and data."""
    def learnt(settings: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in settings.items() if k not in ACTING_ONLY}

    for what, old, new in (("policy", learnt(previous["policy"]), learnt(policy)),
                           ("training", previous["train"], train), ("data", previous["source"], source)):
        if plain(old) != plain(new):
            changed = sorted(k for k in set(old) | set(new) if plain(old.get(k)) != plain(new.get(k)))
            raise FetchError(f"{run} holds a run with other {what} settings ({', '.join(changed)} differ); "
                             "resume it with the same arguments, or train into another --out")


def plain(value: Any) -> Any:
    """`value` as JSON would give it back (tuples as lists, ...): how two sets of settings are compared."""
    return json.loads(json.dumps(value, sort_keys=True))
