"""The crash-safe dataset writer: one file per demo, an index rewritten atomically, one writer at a time.

On disk, an output directory holds `demos.hdf5` (robomimic's layout; each `data/demo_<i>` is an
HDF5 external link) and `episodes/demo_<i>.hdf5`. Every file is written under a temporary name,
flushed to disk and renamed, so a kill at any instant leaves the previous complete version. A demo
counts as saved once the index that lists it is in place; a demo file that a kill left out of
the index is complete (it was renamed after its flush) and is adopted by the next session.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import importlib.metadata
import io
import json
import os
import pathlib
import queue
import shutil
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np

from fetch.dataset import schema
from fetch.dataset.episode import Demo
from fetch.errors import DatasetError

if TYPE_CHECKING:
    from fetch.dataset.frames import RenderPool

VALID_EVERY = 10
"""Every 10th successful demo goes to `mask/valid` (a stable 90/10 split as demos are appended)."""


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


@dataclasses.dataclass
class _Entry:
    name: str
    num_samples: int
    success: bool
    mask: str  # "train", "valid" or "failed"


def fsync_path(path: pathlib.Path) -> None:
    """Flush a file's (or directory's) data to the disk, so a rename after it is durable."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def hdf5_bytes(build: Callable[[h5py.File], None]) -> bytes:
    """An HDF5 file built in memory. Files reach the disk only through `atomic_write`: HDF5 itself
    does not survive a failed write (it crashed the process on a full disk in our tests)."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        build(f)
    return buffer.getvalue()


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


def write_demo_file(path: pathlib.Path, name: str, demo: Demo) -> None:
    """Write one demo as the group `/<name>` of a new HDF5 file, atomically."""
    atomic_write(path, hdf5_bytes(lambda f: write_demo_group(f.create_group(name), demo)))


def write_demo_group(group: h5py.Group, demo: Demo) -> None:
    for key, value in demo.attrs.items():
        group.attrs[key] = value
    for key, array in demo.arrays.items():
        # Images compress well and are large; the rest is small and read often, so stays raw.
        options: dict[str, Any] = {"compression": "gzip", "compression_opts": 4} if array.dtype == np.uint8 \
            and array.ndim == 4 else {}
        group.create_dataset(key, data=array, **options)


MAX_QUEUED = 8
"""Demos that may wait to be saved; `commit` then waits for the writer. Unbounded, a slow disk let
the writer fall 12 demos behind, and a SIGKILL then lost them all (each is an attempt of a person)."""


def lock_directory(directory: pathlib.Path, alternative: str) -> Any:
    """Hold `directory` itself exclusively (an flock on the directory, until `unlock_directory`);
    DatasetError if another collector or tool holds it. `alternative` completes the message
    ("choose another --out"). A lock on a file inside could be bypassed by deleting the file."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
        os.close(fd)
        raise DatasetError(f"{directory} is in use by another collector or tool (it holds the directory's lock); "
                           f"wait for it to finish or {alternative}") from e
    return fd


def unlock_directory(handle: Any) -> None:
    with contextlib.suppress(OSError):
        fcntl.flock(handle, fcntl.LOCK_UN)
    with contextlib.suppress(OSError):
        os.close(handle)


@contextlib.contextmanager
def editing(index: pathlib.Path) -> Iterator[None]:
    """Hold a collector's directory (it has `episodes/` beside `index`) while a tool reads and edits
    it, so no collector appends meanwhile; a single-file dataset needs no lock."""
    if not (index.parent / schema.EPISODES_DIR).is_dir():
        yield
        return
    handle = lock_directory(index.parent, "run it when the collector has finished")
    try:
        yield
    finally:
        unlock_directory(handle)


class Rewrites:
    """Edits of HDF5 files that replace the originals together, when the block ends, or not at all.

    `edit(path)` yields a copy opened for writing; when the `with Rewrites()` block finishes, every
    copy is flushed and renamed over its original, in the order first edited (so edit an index
    last); if the block raises, the copies are deleted and no original has changed.
    """

    def __init__(self) -> None:
        self._copies: dict[pathlib.Path, pathlib.Path] = {}

    @contextlib.contextmanager
    def edit(self, path: pathlib.Path) -> Iterator[h5py.File]:
        tmp = self._copies.get(path)
        if tmp is None:
            tmp = path.with_name(f".{path.name}.tmp")
            self._copies[path] = tmp
            shutil.copyfile(path, tmp)
        with h5py.File(tmp, "r+") as f:
            yield f

    def __enter__(self) -> Rewrites:
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        try:
            if kind is None:
                for tmp in self._copies.values():
                    fsync_path(tmp)
                for path, tmp in self._copies.items():
                    os.replace(tmp, path)
                for directory in {path.parent for path in self._copies}:
                    fsync_path(directory)
        finally:
            for tmp in self._copies.values():
                with contextlib.suppress(OSError):
                    tmp.unlink()


@contextlib.contextmanager
def rewritten(path: pathlib.Path) -> Iterator[h5py.File]:
    """Edit one HDF5 file all at once (see `Rewrites`)."""
    with Rewrites() as rewrites, rewrites.edit(path) as f:
        yield f


def read_demo_group(group: h5py.Group) -> Demo:
    """A saved demo, loaded (the inverse of `write_demo_group`)."""
    arrays: dict[str, np.ndarray] = {}

    def visit(path: str, node: Any) -> None:
        if isinstance(node, h5py.Dataset):
            arrays[path] = node[()]

    group.visititems(visit)
    return Demo(arrays, dict(group.attrs))


class BackgroundWriter:
    """Saves demos from a thread, so committing never stalls the control loop; one per directory.

    `commit` numbers a demo, queues it and returns at once; `_save` (a subclass's) writes it and
    `on_saved(name, demo)` is called from the writing thread once it is durable. A failure stops
    further saving; the next `commit` and `close` raise it. Attempts are counted across sessions.
    """

    def __init__(self, out_dir: str | os.PathLike[str], on_saved: Callable[[str, Demo], None] | None) -> None:
        self.out_dir = pathlib.Path(out_dir)
        self.on_saved = on_saved
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise DatasetError(f"cannot create the output directory {self.out_dir}: {e.strerror}") from e
        self._lock_file = self._lock()
        self.attempts = 0
        self.saved = 0
        self.recovered = 0
        self._next_index = 0
        self.error: BaseException | None = None
        self._pending: list[str] = []
        self._queue: queue.Queue[tuple[str, Demo] | None] = queue.Queue(MAX_QUEUED)
        self.most_behind = 0
        """the most demos that were ever waiting to be saved."""
        self._thread = threading.Thread(target=self._run, name="fetch-dataset-writer", daemon=True)

    def _start(self) -> None:
        self._thread.start()

    def _lock(self) -> Any:
        return lock_directory(self.out_dir, "choose another --out")

    def _unlock(self) -> None:
        if self._lock_file is not None:  # once: the descriptor's number may be reused after close
            unlock_directory(self._lock_file)
            self._lock_file = None

    def reserve_attempt(self) -> int:
        """The number of the attempt about to start."""
        number = self.attempts
        self.attempts += 1
        return number

    def demo_name(self, index: int) -> str:
        return schema.demo_name(index)

    def commit(self, demo: Demo) -> str:
        """Queue a finished demo for saving and return its name; raises the writer's earlier failure."""
        if self.error is not None:
            raise DatasetError(f"saving to {self.out_dir} failed earlier: {self.error}") from self.error
        name = self.demo_name(self._next_index)
        self._next_index += 1
        self._queue.put((name, demo))  # waits while MAX_QUEUED demos are already waiting
        self.most_behind = max(self.most_behind, self._queue.qsize())
        return name

    @property
    def behind(self) -> int:
        """Demos committed but not yet saved."""
        return self._queue.qsize()

    def _run(self) -> None:
        for name in self._pending:  # saved by an earlier session that stopped before completing them
            if self.error is None:
                self._complete_safely(name, None)
        while True:
            item = self._queue.get()
            try:
                if item is None:
                    return
                if self.error is None:
                    name, demo = item
                    try:
                        self._save(name, demo)
                    except OSError as e:
                        self.error = DatasetError(self._describe(name, e))
                        continue
                    except Exception as e:  # a bug must not end the thread silently
                        self.error = e
                        continue
                    self.saved += 1
                    if self.on_saved is not None:
                        self.on_saved(name, demo)
                    self._complete_safely(name, demo)
            finally:
                self._queue.task_done()

    def _complete_safely(self, name: str, demo: Demo | None) -> None:
        try:
            self._complete(name, demo)
        except OSError as e:
            self.error = DatasetError(self._describe(name, e))
        except Exception as e:
            self.error = e

    def _complete(self, name: str, demo: Demo | None) -> None:
        """Called after demo `name` is saved (None: it was saved by an earlier session), to add what
        is made after the fact (a subclass's images)."""

    def _save(self, name: str, demo: Demo) -> None:
        raise NotImplementedError

    def _describe(self, name: str, e: OSError) -> str:
        reason = {errno.EFBIG: "the file-size limit was reached", errno.ENOSPC: "the disk is full",
                  errno.EACCES: "permission denied", errno.EROFS: "the file system is read-only"}.get(
            e.errno or 0, str(e))
        return f"could not save {name} in {self.out_dir}: {reason}; the demos saved before are intact"

    def _finish(self) -> None:
        """Called by `close` after the last save (e.g. to record the attempt count)."""

    def flush(self) -> None:
        """Wait until every committed demo is on disk (or the writer failed)."""
        self._queue.join()

    def close(self) -> None:
        """Finish saving, release the directory; re-raise a failure."""
        self._queue.put(None)
        if self._thread.is_alive():
            self._thread.join()
        try:
            if self.error is None:
                try:
                    self._finish()
                except OSError as e:
                    self.error = DatasetError(self._describe("the index", e))
        finally:
            self._unlock()
        if self.error is not None:
            raise self.error

    def __enter__(self) -> BackgroundWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
        self._renderer: RenderPool | None = None
        self.created = time.time()
        try:
            self.episodes_dir.mkdir(exist_ok=True)
            if self.index_path.exists():
                self._resume()
            else:
                self._refuse_orphans()
                self._write_index()
        except OSError as e:
            self._unlock()
            raise DatasetError(f"cannot write a dataset in {self.out_dir}: {e}") from e
        except BaseException:
            self._unlock()
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

        for stale in self.out_dir.glob(".*.tmp"):
            stale.unlink()
        for stale in self.episodes_dir.glob(".*.tmp"):
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
            try:
                with h5py.File(path, "r") as f:
                    group = f[name]
                    entry = _Entry(name, int(group.attrs["num_samples"]), bool(group.attrs["success"]),
                                   self._mask_for(bool(group.attrs["success"])))
                    self.attempts = max(self.attempts, int(group.attrs["attempt"]) + 1)
            except (OSError, KeyError):
                continue  # not a complete demo file; it was never listed, so nothing is lost
            self._entries.append(entry)
            self._next_index = schema.demo_index(name) + 1
            self.recovered += 1
        if self.recovered:
            self._write_index()

    def _check_matches(self, attrs: dict[str, Any]) -> None:
        h = self.header
        mine = {"env_id": h.env_id, "env_kwargs": h.env_kwargs, "layout": schema.layout_to_json(h.layout),
                "settings": h.settings, "model_hash": h.model_hash}
        differences = [f"{key}: the dataset has {attrs.get(key)!r}, this session {value!r}"
                       for key, value in mine.items() if attrs.get(key) != value]
        if differences:
            raise DatasetError(f"{self.index_path} holds demos recorded differently, so this session cannot "
                               "append to it:\n  " + "\n  ".join(differences)
                               + "\nuse the same settings, or another --out (and `gym-fetch merge` later)")

    # -- masks and the index ------------------------------------------------------------------

    def _mask_for(self, success: bool) -> str:
        if not success:
            return "failed"
        rank = sum(1 for e in self._entries if e.success)
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
        try:
            self._write_index()
        except BaseException:
            # The demo file stays: it is complete, and the next session adopts it.
            self._entries.pop()
            raise

    def _finish(self) -> None:
        self._write_index()  # the attempt count

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
                demo = read_demo_group(f[name])
        cameras = self._images_missing(demo.arrays)
        if not cameras:
            return
        if self._renderer is None:
            from fetch.dataset.frames import RenderPool

            h = self.header
            self._renderer = RenderPool(h.env_id, h.env_kwargs, h.layout.image_size, workers=1, nice=10)
        images = self._renderer.render(demo.arrays["states"], cameras)
        arrays = dict(demo.arrays)
        for camera, frames in images.items():
            arrays[f"obs/{schema.image_key(camera)}"] = frames[:-1]
            arrays[f"next_obs/{schema.image_key(camera)}"] = frames[1:]
        write_demo_file(path, name, Demo(arrays, demo.attrs))

    def close(self) -> None:
        try:
            super().close()
        finally:
            if self._renderer is not None:
                self._renderer.close()


