"""A recording, whatever format `collect` wrote it in: one reader per format behind one interface; and what
`gym-fetch info` prints of it (`inspect_recording`).

`info` and `replay` open a path with `open_recording` and ask the `Recording` what they need (a
summary, its problems, its demos' states, a bit-for-bit check of each), never which format it is.
A new format is a `Recording` class here and one line in `READERS`.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import json
import os
import pathlib
from collections.abc import Callable, Iterator
from typing import Any, Protocol

import numpy as np

from fetch.dataset import npz
from fetch.dataset.reader import Dataset, open_dataset
from fetch.dataset.replay.check import ReplayCheck, check_demo, make_replay_env, other_model, resimulate
from fetch.dataset.schema import episode_seed
from fetch.dataset.validation import require_valid, validate
from fetch.errors import FetchError


class Recording(Protocol):
    """Demos of one env on disk, with `--demo`'s choice among them made."""

    env_id: str
    env_kwargs: dict[str, Any]
    names: list[str]
    """the chosen demos, in order."""

    def summary(self) -> list[str]:
        """`info`'s lines about it (the first names the path)."""

    def problems(self) -> list[str]:
        """What is wrong with it, one line each ([]: valid)."""

    def require_valid(self) -> None:
        """DatasetError if the chosen demos cannot be replayed or rendered as they are."""

    def states(self, name: str) -> np.ndarray:
        """(T+1, D) the saved states of a chosen demo."""

    def seed(self, name: str) -> int | None:
        """A chosen demo's reset seed (what its looks are drawn from, `fetch.looks`), None if it has none."""

    def replay_env(self) -> Any:
        """The env its demos replay on (unwrapped: no time limit)."""

    def note(self, env: Any) -> str | None:
        """Why a replay on `env` need not be exact (another model than the recorded one), or None."""

    def check(self, name: str, env: Any) -> ReplayCheck:
        """Replay a chosen demo on `env` and compare it with what was recorded."""


class Hdf5Recording:
    """The HDF5 dataset (`--format hdf5`, robomimic's layout): a directory or a merged file."""

    def __init__(self, ds: Dataset, demo: str | None) -> None:
        self.ds = ds
        self.env_id, self.env_kwargs = ds.env_id, dict(ds.env_kwargs)
        self.names = ds.select(demo)

    def summary(self) -> list[str]:
        from fetch.dataset import summarize
        from fetch.dataset.habits import dataset_flags, describe_flags

        ds, s = self.ds, summarize(self.ds)
        low, high, mean = s.lengths
        lines = [f"{s.path}", f"  env         {s.env_id} {ds.env_kwargs}",
                 f"  demos       {s.demos} ({s.successful} successful), {s.steps} steps; length min {low} "
                 f"mean {mean:.1f} max {high}",
                 "  masks       " + ", ".join(f"{k} {v}" for k, v in sorted(s.masks.items())),
                 f"  actions     in [{s.action_range[0]:.3f}, {s.action_range[1]:.3f}]",
                 "  devices     " + (", ".join(f"{k} {v}" for k, v in sorted(s.devices.items())) or "-"),
                 f"  control     {s.achieved_hz:.1f} Hz achieved (mean over demos; 0: unpaced)",
                 f"  cameras     {', '.join(s.cameras) or 'none'}"
                 + (f" ({ds.layout.image_size} px, {ds.layout.image_quality} quality)" if s.cameras else "")]
        demos, taken, person, steps = s.corrections
        if demos:
            lines.append(f"  takeovers   {demos} demos recorded with a person ready to take over: {taken} takeovers, "
                         f"{person} of their {steps} steps ({100 * person / max(steps, 1):.0f} %) driven by the person")
        lines += [f"  settings    {ds.settings}",
                  "  versions    " + ", ".join(f"{k} {v}" for k, v in s.versions.items())]
        lines += [line if line.startswith("  ") else "  " + line for line in describe_flags(dataset_flags(ds), s.demos)]
        if unlisted := ds.unlisted():
            lines.append(f"  unlisted    {len(unlisted)} demo file(s) in {unlisted[0].parent.name}/ that the index "
                         f"does not list ({unlisted[0].stem}{'..' + unlisted[-1].stem if len(unlisted) > 1 else ''}): "
                         "a session stopped before it rewrote the index; the next `gym-fetch collect` on this "
                         "directory checks them and takes them in")
        return lines

    def problems(self) -> list[str]:
        return validate(self.ds)

    def require_valid(self) -> None:
        require_valid(self.ds, self.names, images=False)

    def states(self, name: str) -> np.ndarray:
        return np.asarray(self.ds.demo(name)["states"][()])

    def seed(self, name: str) -> int | None:
        return episode_seed(self.ds.attrs(name))

    def replay_env(self) -> Any:
        return make_replay_env(self.ds)

    def note(self, env: Any) -> str | None:
        return other_model(self.ds, env)

    def check(self, name: str, env: Any) -> ReplayCheck:
        return check_demo(self.ds, name, env)


class NpzRecording:
    """The seed collector's per-demo files (`--format npz`): a directory of them, or one file."""

    def __init__(self, path: str | os.PathLike[str], files: list[pathlib.Path], demo: str | None) -> None:
        self.path = pathlib.Path(path)
        self.all = [npz.load_npz(f) for f in files]
        chosen = self.all
        if demo is not None:
            chosen = [d for d in self.all if demo in (d.path.stem, d.path.name)]
            if not chosen:
                raise FetchError(f"no demo file {demo!r}; this directory has "
                                 f"{', '.join(f.stem for f in files[:5])}" + (" ..." if len(files) > 5 else ""))
        self.demos = {d.path.stem: d for d in chosen}
        self.names = list(self.demos)
        self.env_id = str(chosen[0].metadata["env_id"])
        self.env_kwargs: dict[str, Any] = {}  # collect_fetch_demo.py's files record none

    def summary(self) -> list[str]:
        demos = self.all
        lengths = [d.steps for d in demos]
        devices = collections.Counter(str(d.metadata.get("device", "?")) for d in demos)
        successful = sum(bool(d.metadata.get("successful", d.metadata.get("success", False))) for d in demos)
        seeds = ", ".join(str(d.metadata["seed"]) for d in demos[:20])
        return [f"{self.path} (npz: one file per demo, collect_fetch_demo.py's format)",
                f"  env         {', '.join(self._envs())}",
                f"  demos       {len(demos)} ({successful} successful), {sum(lengths)} steps; length min "
                f"{min(lengths)} mean {sum(lengths) / len(lengths):.1f} max {max(lengths)}",
                "  devices     " + ", ".join(f"{k} {v}" for k, v in sorted(devices.items())),
                f"  seeds       {seeds}" + (" ..." if len(demos) > 20 else "")]

    def _envs(self) -> list[str]:
        return sorted({str(d.metadata["env_id"]) for d in self.all})

    def problems(self) -> list[str]:
        found = [p for d in self.all for p in npz.problems(d)]
        if len(envs := self._envs()) > 1:
            found.append(f"the files are of {len(envs)} envs: {', '.join(envs)}")
        return found

    def require_valid(self) -> None:
        """Each file was checked to be readable and to hold what a replay needs when it was loaded."""

    def states(self, name: str) -> np.ndarray:
        return self.demos[name].arrays["states"]

    def seed(self, name: str) -> int | None:
        return episode_seed(self.demos[name].metadata)

    def replay_env(self) -> Any:
        import gymnasium as gym

        import fetch  # noqa: F401  (registers the ids)

        return gym.make(self.env_id).unwrapped

    def note(self, env: Any) -> str | None:
        return None  # collect_fetch_demo.py's files record no model hash

    def check(self, name: str, env: Any) -> ReplayCheck:
        return check_npz(self.demos[name], env)


def check_npz(demo: npz.NpzDemo, env: Any) -> ReplayCheck:
    """Replay one file as `replay --check` does an HDF5 demo (`replay.check.resimulate`)."""
    a = demo.arrays
    keys = [k[len("obs__"):] for k in a if k.startswith("obs__")]
    recorded = any(float(i.get("is_success", 0.0)) >= 1.0 for i in json.loads(str(a["info_json"])))
    return resimulate(demo.path.name, env, int(demo.metadata["seed"]), a["action"], a["states"],
                      first={k: a[f"obs__{k}"][:1] for k in keys}, recorded_next={k: a[f"obs__{k}"][1:] for k in keys},
                      success_recorded=recorded)


def _open_npz(path: pathlib.Path, demo: str | None) -> contextlib.AbstractContextManager[Recording]:
    return contextlib.nullcontext(NpzRecording(path, npz.npz_files(path), demo))


@contextlib.contextmanager
def _open_hdf5(path: pathlib.Path, demo: str | None) -> Iterator[Recording]:
    with open_dataset(path) as ds:
        yield Hdf5Recording(ds, demo)


@dataclasses.dataclass(frozen=True)
class Reader:
    format: str
    holds: Callable[[pathlib.Path], bool]
    """whether a path holds a recording of this format."""
    open: Callable[[pathlib.Path, str | None], contextlib.AbstractContextManager[Recording]]


READERS: tuple[Reader, ...] = (
    Reader("npz", lambda p: bool(npz.npz_files(p)), _open_npz),
    Reader("hdf5", lambda p: True, _open_hdf5),  # last: its reader says what is wrong with anything else
)
"""One reader per format `collect --format` writes, tried in order."""


def open_recording(path: str | os.PathLike[str],
                   demo: str | None = None) -> contextlib.AbstractContextManager[Recording]:
    """The recording at `path`, in whichever format it is, with `demo` (an index or name; None: all) chosen."""
    p = pathlib.Path(path)
    return next(r for r in READERS if r.holds(p)).open(p, demo)


@dataclasses.dataclass(frozen=True)
class RecordingInfo:
    """What `gym-fetch info` says of a recording."""

    summary: tuple[str, ...]
    """its lines (the first names the path)."""
    problems: tuple[str, ...]
    """what is wrong with it, one line each (none: valid)."""


def inspect_recording(path: str | os.PathLike[str]) -> RecordingInfo:
    """The summary and the problems of the recording at `path`, whichever format it is in."""
    with open_recording(path) as recording:
        return RecordingInfo(tuple(recording.summary()), tuple(recording.problems()))
