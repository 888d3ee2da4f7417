"""The saving thread every dataset format shares: `commit` returns at once, demos are written in
order behind it, at most `MAX_QUEUED` wait, a failure stops saving and is raised on the next call."""

from __future__ import annotations

import collections
import contextlib
import os
import pathlib
import queue
import threading
from collections.abc import Callable
from typing import Any

from fetch._durable import lock_directory, temporary, unlock_directory, why
from fetch.dataset import schema
from fetch.dataset.episode import Demo
from fetch.errors import DatasetError

MAX_QUEUED = 8
"""Demos that may wait to be saved; `commit` then waits for the writer. Unbounded, a slow disk let
the writer fall 12 demos behind, and a SIGKILL then lost them all (each is an attempt of a person)."""


IDLE_PUBLISH = 0.5
"""[s] a writer with saved but unpublished demos publishes them once no demo has come for this long
(a person between attempts), whatever `_publish_due` says."""

_FLUSH = ("", None)
"""Queued by `flush`: publish what is saved."""


def require_writable(directory: pathlib.Path) -> None:
    """DatasetError now, before an attempt is made, unless files can be made in `directory`: without
    write access (a read-only dataset, as a user other than its owner; root writes through) the
    collector ran the attempt and failed at its first save. A hidden file made and removed tells."""
    try:
        temporary(directory / "probe").unlink()  # a fresh name: never a file planted at a known one
    except OSError as e:
        raise DatasetError(f"cannot write in {directory}: {why(e)} (nothing was recorded)") from e


class BackgroundWriter:
    """Saves demos from a thread, so committing never stalls the control loop; one per directory.

    `commit` numbers a demo, queues it and returns at once; `_save` (a subclass's) makes it durable
    and `_publish` makes saved demos part of the dataset (the index that lists them), when
    `_publish_due` says so, when no demo has come for `IDLE_PUBLISH`, on `flush` and on `close`;
    `on_saved(name, demo)` is called from the writing thread for each demo once it is published,
    and `saved` counts them. Batching the index keeps a commit's cost independent of the dataset's
    size. A failure stops further saving; the next `commit` and `close` raise it. Attempts are
    counted across sessions.
    """

    def __init__(self, out_dir: str | os.PathLike[str], on_saved: Callable[[str, Demo], None] | None) -> None:
        self.out_dir = pathlib.Path(out_dir)
        self.on_saved = on_saved
        self._lock_file: Any = None
        self._made_out_dir = not self.out_dir.exists()
        """the directory is this writer's: a failure (or a stop) before its first file is published removes it."""
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise DatasetError(f"cannot create the output directory {self.out_dir}: {e.strerror}") from e
        self._lock_file = self._lock()
        try:
            require_writable(self.out_dir)
        except BaseException:
            self._abandon()
            raise
        self.attempts = 0
        self.saved = 0
        self.recovered = 0
        self._next_index = 0
        self.error: BaseException | None = None
        self._pending: list[str] = []
        self._queue: queue.Queue[tuple[str, Demo | None] | None] = queue.Queue(MAX_QUEUED)
        self._unpublished: list[tuple[str, Demo]] = []
        self._unsaved: collections.deque[str] = collections.deque()
        """demos committed and not yet published, in order: the first is the one a failure did not save."""
        self._images_failed: tuple[str, str] | None = None
        """(demo, reason) when adding a saved demo's images (`_complete`) failed."""
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

    def _abandon(self) -> None:
        """Give the directory up before anything was published in it: if this writer made it and holds its
        lock, it is removed with what the writer put there (empty folders, half-written `.tmp` files), so a
        stop or a failure while starting leaves no directory that is not a dataset (a Ctrl-C a moment after
        `collect` started left an empty `--out`). Removed before the lock is let go: another writer that
        takes the lock next makes its own."""
        if self._made_out_dir and self._lock_file is not None:
            with contextlib.suppress(OSError):
                for tmp in self.out_dir.rglob(".*.tmp"):
                    tmp.unlink()
                for folder in sorted(self.out_dir.rglob("*"), key=lambda q: len(q.parts), reverse=True):
                    if folder.is_dir() and not folder.is_symlink():
                        folder.rmdir()
                self.out_dir.rmdir()
        self._unlock()

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
            error = self._failure()
            raise DatasetError(f"saving to {self.out_dir} failed earlier: {error}") from error
        name = self.demo_name(self._next_index)
        self._next_index += 1
        self._unsaved.append(name)
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
            try:
                item = self._queue.get(timeout=IDLE_PUBLISH if self._unpublished else None)
            except queue.Empty:
                self._publish_safely()
                continue
            try:
                if item is None or item is _FLUSH:
                    self._publish_safely()
                    if item is None:
                        return
                elif self.error is None:
                    name, demo = item
                    assert demo is not None
                    try:
                        self._save(name, demo)
                    except OSError as e:
                        # The demos saved before it are listed first, so the count is what is on disk.
                        self._publish_safely(complete=False)
                        if self.error is None:
                            self.error = DatasetError(self._describe(name, e))
                        continue
                    except BaseException as e:  # a bug (or a worker's KeyboardInterrupt) must not end the thread
                        self.error = e
                        continue
                    self._unpublished.append((name, demo))
                    if self._publish_due(len(self._unpublished)):
                        self._publish_safely()
            finally:
                self._queue.task_done()

    def _publish_safely(self, complete: bool = True) -> None:
        """Publish the saved demos, then (`complete`) add what is made after the fact (their images)."""
        batch, self._unpublished = self._unpublished, []
        if not batch or self.error is not None:
            return
        try:
            self._publish([name for name, _ in batch])
        except OSError as e:
            self.error = DatasetError(self._describe_unpublished([name for name, _ in batch], e))
            return
        except BaseException as e:
            self.error = e
            return
        for name, demo in batch:
            self.saved += 1
            self._unsaved.popleft()  # published in the order committed
            if self.on_saved is not None:
                with contextlib.suppress(Exception):  # the demo is saved; only the news of it failed
                    self.on_saved(name, demo)
        for name, demo in batch:
            if complete and self.error is None:
                self._complete_safely(name, demo)

    def _publish_due(self, unpublished: int) -> bool:
        """Whether to publish the `unpublished` saved demos now (default: each at once)."""
        return True

    def _publish(self, names: list[str]) -> None:
        """Make the saved demos `names` part of the dataset (default: saving did)."""

    def _complete_safely(self, name: str, demo: Demo | None) -> None:
        try:
            self._complete(name, demo)
        except OSError as e:
            # `name` is saved (listed in the index); what failed is only what is added after the fact.
            self._images_failed = (name, why(e))
            self.error = DatasetError(f"could not add {name}'s images in {self.out_dir}: {self._images_failed[1]}; "
                                      f"{self._images_note(name)}, and the demos saved before are intact")
        except BaseException as e:  # a KeyboardInterrupt from a worker comes back through its future
            self.error = e

    def _complete(self, name: str, demo: Demo | None) -> None:
        """Called after demo `name` is saved (None: it was saved by an earlier session), to add what
        is made after the fact (a subclass's images)."""

    def _save(self, name: str, demo: Demo) -> None:
        raise NotImplementedError

    def _describe(self, name: str, e: OSError) -> str:
        return f"could not save {name} in {self.out_dir}: {why(e)}; the demos saved before are intact"

    def _describe_unpublished(self, names: list[str], e: OSError) -> str:
        """Why the saved demos `names` could not be published (`_publish` failed)."""
        return self._describe(names[0], e)

    def _images_note(self, name: str) -> str:
        return f"{name} is saved without its images (the next session in this directory adds them)"

    def _failure(self) -> BaseException:
        """The failure to raise. When adding a saved demo's images failed, saving stopped there: it names
        the first demo committed after it that is not saved (the one a person would miss), if any."""
        assert self.error is not None
        unsaved = list(self._unsaved)
        if self._images_failed is None or not unsaved:
            return self.error
        name, reason = self._images_failed
        after = len(unsaved) - 1
        more = f" (nor the {after} demo{'s' if after > 1 else ''} after it)" if after else ""
        return DatasetError(f"could not save {unsaved[0]}{more} in {self.out_dir}: {reason} while {name}'s images "
                            f"were added; {self._images_note(name)}, and the demos saved before are intact")

    def _finish(self) -> None:
        """Called by `close` after the last save (e.g. to record the attempt count)."""

    def flush(self) -> None:
        """Wait until every committed demo is on disk and published (or the writer failed)."""
        self._queue.put(_FLUSH)
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
            error = self._failure()
            if error is self.error:
                raise error
            raise error from self.error

    def __enter__(self) -> BackgroundWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
