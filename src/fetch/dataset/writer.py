"""The crash-safe dataset writer: one file per demo, an index rewritten atomically, one writer at a time.

On disk, an output directory holds `demos.hdf5` (robomimic's layout; each `data/demo_<i>` is an
HDF5 external link) and `episodes/demo_<i>.hdf5`. Every file is written under a temporary name,
flushed to disk and renamed, so a kill at any instant leaves the previous complete version. A demo
counts as saved once the index that lists it is in place; a demo file that a kill left out of
the index is complete (it was renamed after its flush) and is adopted by the next session.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import importlib.metadata
import json
import os
import pathlib
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np

from fetch._confine import require_no_link
from fetch._durable import atomic_write, why
from fetch.dataset import schema
from fetch.dataset.background import BackgroundWriter, require_writable
from fetch.dataset.demo_file import hdf5_bytes, read_demo_group, write_demo_file
from fetch.dataset.episode import Demo
from fetch.dataset.holding import finish_rewrites
from fetch.dataset.sealed import check_sealed
from fetch.errors import DatasetError

if TYPE_CHECKING:
    from fetch.dataset.render.frames import RenderPool

VALID_EVERY = 10
"""Every 10th successful demo goes to `mask/valid` (a stable 90/10 split as demos are appended)."""

INDEX_BATCH = 8
"""The index is rewritten once the demos saved since it was last written reach 1/8 of the dataset
(or the writer is idle, `background.IDLE_PUBLISH`): each demo then pays for ~8 index entries,
however large the dataset; every demo at once, as before, is O(N) per demo."""


@dataclasses.dataclass(frozen=True)
class Header:
    """What a dataset is of: the env, the recorded layout, the settings a resumed session must match."""

    env_id: str
    env_kwargs: dict[str, Any]
    layout: schema.Layout
    settings: dict[str, Any]
    model_xml: str
    model_hash: str
    versions: dict[str, str]
    legacy_model_hash: str = ""
    """The same model's hash as datasets recorded before `model_hash` became install-independent have
    it: such a dataset still takes appends from this install."""

    def env_args(self) -> str:
        return json.dumps({"env_name": self.env_id, "type": schema.ENV_TYPE_GYM, "env_kwargs": self.env_kwargs})


def package_versions() -> dict[str, str]:
    """The versions a dataset records as having made it (`data.attrs['versions']`)."""
    import gymnasium
    import mujoco

    import fetch

    return {"fetch": fetch.__version__, "mujoco": mujoco.__version__, "gymnasium": gymnasium.__version__,
            "numpy": np.__version__, "h5py": h5py.__version__,
            "gymnasium_robotics": importlib.metadata.version("gymnasium-robotics"),
            "python": sys.version.split()[0]}


def _differences(key: str, theirs: Any, mine: Any) -> list[str]:
    """One line per setting that differs between a dataset's record and this session's, nested settings named by
    their path (`settings.generate.noise`), so the one that differs is found at a glance."""
    if isinstance(theirs, dict) and isinstance(mine, dict):
        return [line for name in sorted(set(theirs) | set(mine), key=str)
                for line in _differences(f"{key}.{name}", theirs.get(name, _ABSENT), mine.get(name, _ABSENT))]
    if theirs == mine:
        return []
    return [f"{key}: the dataset has {theirs!r}, this session {mine!r}"]


class _Absent:
    def __repr__(self) -> str:
        return "(none)"


_ABSENT = _Absent()


def _same_layout(recorded: Any, layout: schema.Layout) -> bool:
    """Whether a dataset's layout attribute describes `layout` (its JSON may predate a field)."""
    try:
        return isinstance(recorded, str) and schema.layout_from_json(recorded) == layout
    except (ValueError, KeyError, TypeError):
        return False


@dataclasses.dataclass
class _Entry:
    name: str
    num_samples: int
    success: bool
    mask: str  # "train", "valid" or "failed"


class DatasetWriter(BackgroundWriter):
    """Appends demos to a robomimic-layout dataset in `out_dir` (see the module docstring).

    Raises DatasetError if another writer holds the directory, or if it already holds a dataset of
    a different env, layout or settings.
    """

    def __init__(self, out_dir: str | os.PathLike[str], header: Header,
                 on_saved: Callable[[str, Demo], None] | None = None) -> None:
        super().__init__(out_dir, on_saved)
        self.index_path = self.out_dir / schema.INDEX_NAME
        self.episodes_dir = self.out_dir / schema.EPISODES_DIR
        self.header = header
        self._entries: list[_Entry] = []
        self._successes = 0
        self._renderer: RenderPool | None = None
        self.created = time.time()
        try:
            require_no_link(self.index_path, "the dataset's index")  # a stranger's folder: never written through
            require_no_link(self.episodes_dir, "the dataset's folder of demo files")
            self.episodes_dir.mkdir(exist_ok=True)
            require_writable(self.episodes_dir)
            if self.index_path.exists():
                self._resume()
            else:
                self._refuse_orphans()
                self._write_index()
        except OSError as e:
            self._abandon()
            raise DatasetError(f"cannot write a dataset in {self.out_dir}: {e}") from e
        except BaseException:
            self._abandon()
            raise
        self.saved = len(self._entries)
        self._start()

    # -- resume -------------------------------------------------------------------------------

    def _refuse_orphans(self) -> None:
        """No index, but demo files (the index deleted, or a dangling link): a new dataset would
        overwrite them from demo_0 on, so refuse, naming what is there."""
        found = sorted(self.episodes_dir.glob("demo_*.hdf5"))
        if self.index_path.is_symlink():
            raise DatasetError(f"{self.index_path} is a link to {os.readlink(self.index_path)}, which does not "
                               "exist; restore it or choose another --out (nothing was written)")
        if found:
            raise DatasetError(f"{self.out_dir} has {len(found)} demo file(s) in {schema.EPISODES_DIR}/ (e.g. "
                               f"{found[0].name}) but no {schema.INDEX_NAME} listing them; a new dataset would "
                               f"overwrite them. Restore {schema.INDEX_NAME}, move {schema.EPISODES_DIR}/ away, or "
                               "choose another --out (nothing was written)")

    def _resume(self) -> None:
        from fetch.dataset.reader import open_dataset

        finish_rewrites(self.index_path)  # an edit's renames that a kill stopped part-way: its copies are .tmp
        for stale in [*self.out_dir.glob(".*.tmp"), *self.episodes_dir.glob(".*.tmp")]:
            if stale.is_file() and not stale.is_symlink():  # what an edit or a save left; never a planted folder
                stale.unlink()
        with open_dataset(self.index_path) as existing:
            self._check_matches(existing.header_attrs())
            inside = [n for n in existing.demo_names if existing.demo_file(n)[0] == existing.path]
            if inside:
                raise DatasetError(f"{self.index_path} holds its demos inside the file (a `gym-fetch merge` output, "
                                   "not a collector's directory), so a collector cannot append to it; collect "
                                   "into another --out and merge the two")
            masks = existing.masks()
            for name in existing.demo_names:
                group = existing.demo(name)
                success = bool(group.attrs["success"])
                mask = next((k for k in schema.SPLITS if name in masks.get(k, ())),
                            self._mask_for(success))
                self._entries.append(_Entry(name, int(group.attrs["num_samples"]), success, mask))
            self.attempts = int(existing.data_attrs.get("attempts", 0))
            self.created = float(existing.data_attrs.get("created", self.created))
            self._pending = [name for name in existing.demo_names if self._images_missing(existing.demo(name))]
        known = {e.name for e in self._entries}
        self._next_index = 1 + max((schema.demo_index(e.name) for e in self._entries), default=-1)
        # Demo files renamed into place just before a kill, while the index was being rewritten.
        orphans = []
        for path in self.episodes_dir.glob("demo_*.hdf5"):
            name = path.stem
            with contextlib.suppress(ValueError):
                if name not in known and schema.demo_index(name) >= self._next_index:
                    orphans.append((schema.demo_index(name), name, path))
        for _, name, path in sorted(orphans):
            if not path.is_file() or path.is_symlink():
                raise DatasetError(f"{path} is not a regular file; a demo file is an HDF5 file. Move it away "
                                   "(nothing was written)")
            # A demo file is renamed into place whole (`write_demo_file`): one that cannot be read, or
            # lacks its group, was put there by something else, and saving demo_N would overwrite it.
            try:
                with h5py.File(path, "r") as f:
                    check_sealed(f, str(path))
                    if not isinstance(f.get(name), h5py.Group):
                        raise DatasetError(f"{path} is not a demo of this dataset (it has no group {name!r}), so "
                                           "it is not taken in, and the next demo would overwrite it; move it away "
                                           "(nothing was written)")
                    samples, success, attempt = self._check_orphan(path, name, f)
            except OSError as e:
                raise DatasetError(f"{path} is not a demo of this dataset (not an HDF5 file: "
                                   f"{' '.join(str(e).split())[:120]}), so it is not taken in, and the next demo "
                                   "would overwrite it; move it away (nothing was written)") from e
            entry = _Entry(name, samples, success, self._mask_for(success))
            self.attempts = max(self.attempts, attempt + 1)
            self._entries.append(entry)
            self._next_index = schema.demo_index(name) + 1
            self.recovered += 1
        if self.recovered:
            self._write_index()

    def _check_orphan(self, path: pathlib.Path, name: str, f: h5py.File) -> tuple[int, bool, int]:
        """(steps, success, attempt) of a demo file a kill left out of the index, after checking it is a
        complete demo of this dataset: one found there that is not (another env's demo, a stub, arrays of
        the wrong size) is refused, naming the problem, rather than taken in (every tool would then refuse
        the dataset, and a stub's attempt number would shift every later seed). A demo file is its own
        group `name` with the attributes and arrays every demo has."""
        group = f[name]
        attrs = group.attrs

        def problem(what: str) -> DatasetError:
            return DatasetError(f"{path} is not a demo of this dataset ({what}), so it is not taken in; move it "
                                "away (nothing was written)")

        if attrs.get("env_id") != self.header.env_id:
            raise problem(f"its env_id is {attrs.get('env_id')!r}, the dataset's {self.header.env_id!r}")
        missing = [k for k in ("num_samples", "success", "attempt", "seed") if k not in attrs]
        if missing:
            raise problem(f"it has no attribute {missing[0]!r}")
        samples, attempt = int(attrs["num_samples"]), int(attrs["attempt"])
        if samples < 0 or attempt < 0:
            raise problem(f"num_samples {samples}, attempt {attempt}")
        layout = self.header.layout
        expected = {"actions": (samples, 4), "states": (samples + 1, layout.state_size),
                    **{f"obs/{k}": (samples, n) for k, n in layout.obs_sizes}}
        for key, shape in expected.items():
            found = group.get(key)
            if not isinstance(found, h5py.Dataset) or found.shape != shape:
                raise problem(f"{key} is {None if found is None else getattr(found, 'shape', 'not an array')}, "
                              f"not {shape}")
        return samples, bool(attrs["success"]), attempt

    def _check_matches(self, attrs: dict[str, Any]) -> None:
        h = self.header
        mine = {"env_id": h.env_id, "env_kwargs": h.env_kwargs, "layout": schema.layout_to_json(h.layout),
                "settings": h.settings, "model_hash": h.model_hash}
        if h.legacy_model_hash and attrs.get("model_hash") == h.legacy_model_hash:
            mine["model_hash"] = h.legacy_model_hash  # recorded before the hash was install-independent
        if _same_layout(attrs.get("layout"), h.layout):
            mine["layout"] = attrs["layout"]  # the same layout, written before image_quality existed
        differences = [line for key, value in mine.items() for line in _differences(key, attrs.get(key), value)]
        if differences:
            raise DatasetError(f"{self.index_path} holds demos recorded differently, so this session cannot "
                               "append to it:\n  " + "\n  ".join(differences)
                               + "\nuse the same settings, or another --out (and `gym-fetch merge` later)")

    # -- masks and the index ------------------------------------------------------------------

    def _mask_for(self, success: bool) -> str:
        """The split of the next demo: every `VALID_EVERY`th success is "valid"."""
        if not success:
            return "failed"
        rank = self._successes
        self._successes += 1
        return "valid" if rank % VALID_EVERY == VALID_EVERY - 1 else "train"

    def _write_index(self) -> None:
        atomic_write(self.index_path, hdf5_bytes(self._build_index))

    def _build_index(self, f: h5py.File) -> None:
        h = self.header
        data = f.create_group("data")
        attrs = {
            "total": sum(e.num_samples for e in self._entries),
            "env_args": h.env_args(),
            "format": schema.FORMAT,
            "format_version": schema.FORMAT_VERSION,
            "versions": json.dumps(h.versions),
            "created": self.created,
            "settings": json.dumps(h.settings, sort_keys=True),
            "layout": schema.layout_to_json(h.layout),
            "model_xml": h.model_xml,
            "model_hash": h.model_hash,
            "attempts": self.attempts,
        }
        for key, value in attrs.items():
            data.attrs[key] = value
        links = data.id.links
        for e in self._entries:
            target = f"{schema.EPISODES_DIR}/{e.name}.hdf5".encode()
            links.create_external(e.name.encode(), target, f"/{e.name}".encode())
        mask = f.create_group("mask")
        for key in schema.SPLITS:
            names = [e.name for e in self._entries if e.mask == key]
            mask.create_dataset(key, data=np.array(names, dtype="S"), shape=(len(names),),
                                dtype=f"S{max((len(n) for n in names), default=1)}")

    def _save(self, name: str, demo: Demo) -> None:
        write_demo_file(self.episodes_dir / f"{name}.hdf5", name, demo)
        self._entries.append(_Entry(name, demo.num_samples, demo.success, self._mask_for(demo.success)))

    def _publish_due(self, unpublished: int) -> bool:
        # Rewriting the index costs ~70 us per listed demo: rewritten every `INDEX_BATCH`-th of the
        # dataset's size, each demo's share of that cost stays the same at 100 or 100,000 demos.
        return unpublished * INDEX_BATCH >= len(self._entries)

    def _publish(self, names: list[str]) -> None:
        try:
            self._write_index()
        except BaseException:
            # The demo files stay: they are complete, and the next session adopts them.
            del self._entries[len(self._entries) - len(names):]
            raise

    def _finish(self) -> None:
        self._write_index()  # the attempt count

    def _describe_unpublished(self, names: list[str], e: OSError) -> str:
        files, them = ((f"{names[0]}'s file is", "it") if len(names) == 1
                       else (f"the files of {names[0]} to {names[-1]} are", "them"))
        return (f"could not save {names[0]} in {self.out_dir}: {why(e)} while the index was rewritten; "
                f"{files} kept in {schema.EPISODES_DIR}/ and the next session in this directory takes {them} in, "
                "and the demos saved before are intact")

    # -- images -------------------------------------------------------------------------------
    # With cameras, a demo is saved first without its images, so it is durable as soon as the
    # attempt ends; its images are then rendered from its saved states in a separate process (off
    # the control loop and its GIL) and the demo's file is replaced by one with them. A session
    # stopped before that leaves demos without images; the next session on the same directory
    # renders them first.

    def _images_missing(self, group: Any) -> list[str]:
        return [c for c in self.header.layout.cameras if f"obs/{schema.image_key(c)}" not in group]

    def _complete(self, name: str, demo: Demo | None) -> None:
        path = self.episodes_dir / f"{name}.hdf5"
        if demo is None:
            with h5py.File(path, "r") as f:
                check_sealed(f, str(path))
                demo = read_demo_group(f[name])
        cameras = self._images_missing(demo.arrays)
        if not cameras:
            return
        images = self._render(name, demo.arrays["states"], cameras, schema.episode_seed(demo.attrs))
        arrays = dict(demo.arrays)
        for camera, frames in images.items():
            arrays[f"obs/{schema.image_key(camera)}"] = frames[:-1]
            arrays[f"next_obs/{schema.image_key(camera)}"] = frames[1:]
        write_demo_file(path, name, Demo(arrays, demo.attrs))

    def _render(self, name: str, states: np.ndarray, cameras: list[str], seed: int | None) -> dict[str, np.ndarray]:
        """A demo's images, from a worker process; one that dies is replaced, as render_ahead's are."""
        from fetch.dataset.render.frames import RenderPool
        from fetch.dataset.render.render_ahead import RESTARTS

        if self._renderer is None:
            h = self.header
            self._renderer = RenderPool(h.env_id, h.env_kwargs, h.layout.image_size, workers=1, nice=10,
                                        quality=h.layout.image_quality)
        restarts = RESTARTS
        while True:
            try:
                return self._renderer.submit(states, cameras, seed).result()
            except concurrent.futures.process.BrokenProcessPool as e:
                if not restarts:  # the demo stays saved without images; the next session renders them
                    self._renderer.close()
                    self._renderer = None
                    raise DatasetError(f"the render worker died while rendering {name}'s images, after "
                                       f"{RESTARTS} restarts: {e}") from e
                restarts -= 1
                print(f"the render worker died while rendering {name}'s images; starting a new one "
                      f"({restarts} more restart(s) allowed)", file=sys.stderr, flush=True)
                self._renderer.replace_workers()

    def close(self) -> None:
        try:
            super().close()
        finally:
            if self._renderer is not None:
                self._renderer.close()


