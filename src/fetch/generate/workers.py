"""Where attempts run: in this process, in a pool of processes, or as Ray actors on a cluster.

Every backend yields results in attempt order (attempt n always resets with seed + n and draws
from its own random stream), so what is kept does not depend on how many workers made it.
Attempts go out in chunks; a bounded window of chunks is in flight, the oldest awaited first. A
worker process that dies (killed, out of memory) is replaced and its chunks made again, the same.
"""

from __future__ import annotations

import collections
import concurrent.futures
import dataclasses
import itertools
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any, Protocol

from fetch._processes import start_worker, stop_pool, workers_deaf_to_ctrl_c
from fetch.errors import FetchError, install_hint
from fetch.generate.attempt import Generator, Options, Result
from fetch.generate.sources import Sources
from fetch.rendering import DEFAULT_IMAGE_QUALITY

CHUNK = 4
"""Attempts per task sent to a worker."""
WINDOW = 3
"""Chunks in flight per worker: enough to keep it busy while the oldest is awaited."""
RESTARTS = 2
"""How often a pool is started again after one of its workers died, making the chunks in flight again
(as the render workers do). A death that comes back every time still ends the run, with a clear error."""


@dataclasses.dataclass(frozen=True)
class Work:
    """What every worker needs to make any attempt (pickled once per worker)."""

    sources: Sources
    options: Options
    seed: int
    cameras: tuple[str, ...] = ()
    """whose images each successful attempt renders, in the worker (checked by `generate`)."""
    image_size: int = 0
    """[px] their width and height."""
    image_quality: str = DEFAULT_IMAGE_QUALITY
    """how they are drawn (`rendering.IMAGE_QUALITIES`)."""

    def generator(self) -> Generator:
        s = self.sources
        return Generator(s.env_id, s.env_kwargs, s.segments, self.options, self.seed, self.cameras, self.image_size,
                         self.image_quality)


def _one_gl_thread() -> None:
    """In a worker process: software GL (llvmpipe) renders with one thread, as the render workers do
    (`dataset.render.frames`), so that K workers on K cores do not contend; unless the user set it."""
    os.environ.setdefault("LP_NUM_THREADS", "1")


class Backend(Protocol):
    workers: int

    def results(self, first: int) -> Iterator[Result]:
        """Attempts first, first + 1, ... in order, for as long as the caller iterates."""

    def close(self) -> None: ...


def default_workers() -> int:
    from fetch._processes import usable_cores

    return usable_cores()


class Serial:
    """Every attempt in this process (one worker)."""

    workers = 1

    def __init__(self, work: Work) -> None:
        self.generator = work.generator()

    def results(self, first: int) -> Iterator[Result]:
        for number in itertools.count(first):
            yield self.generator.attempt(number)

    def close(self) -> None:
        self.generator.close()


_worker: Generator | None = None


def _init_worker(work: Work, nice: int, parent: int) -> None:
    global _worker
    start_worker(parent)  # Ctrl-C reaches the whole process group: the driver stops the pool
    if nice:
        os.nice(nice)
    _one_gl_thread()
    _worker = work.generator()


def _run_chunk(first: int, count: int) -> list[Result]:
    assert _worker is not None
    return [_worker.attempt(n) for n in range(first, first + count)]


@dataclasses.dataclass
class _Chunk:
    start: int
    """its first attempt."""
    future: Any = None
    """None until submitted to the current workers."""


def _ordered(submit: Any, wait: Any, workers: int, first: int,
             replace: Callable[[range, BaseException], None] | None = None) -> Iterator[Result]:
    """Keep WINDOW chunks per worker in flight; yield their results oldest chunk first. Where a dead
    worker broke the pool, `replace` (given the attempts in flight) starts new workers and every chunk
    in flight is sent again: an attempt's result depends on its number alone, not on who made it."""
    pending: collections.deque[_Chunk] = collections.deque()
    starts = itertools.count(first, CHUNK)
    while True:
        try:
            while len(pending) < WINDOW * workers:
                pending.append(_Chunk(next(starts)))
            for chunk in pending:
                if chunk.future is None:
                    chunk.future = submit(chunk.start, CHUNK)
            results = wait(pending[0].future)
        except concurrent.futures.process.BrokenProcessPool as e:
            if replace is None:
                raise
            replace(range(pending[0].start, pending[-1].start + CHUNK), e)
            for chunk in pending:
                chunk.future = None
            continue
        pending.popleft()
        yield from results


class Pool:
    """Attempts in `workers` processes (spawned: no threads or GL state inherited). A worker that dies
    is replaced `RESTARTS` times at most (said on stderr); then the run stops with a `FetchError`."""

    def __init__(self, work: Work, workers: int, nice: int = 0) -> None:
        self.workers = workers
        self.restarts = RESTARTS
        self._initargs = (work, nice, os.getpid())
        self.executor = self._start()

    def _start(self) -> concurrent.futures.ProcessPoolExecutor:
        return concurrent.futures.ProcessPoolExecutor(
            self.workers, mp_context=multiprocessing.get_context("spawn"), initializer=_init_worker,
            initargs=self._initargs)

    def results(self, first: int) -> Iterator[Result]:
        return _ordered(self._submit, lambda future: future.result(), self.workers, first, self._replace)

    def _submit(self, start: int, n: int) -> concurrent.futures.Future[list[Result]]:
        with workers_deaf_to_ctrl_c():  # the new workers a submit starts, after a replace too
            return self.executor.submit(_run_chunk, start, n)

    def _replace(self, attempts: range, error: BaseException) -> None:
        """Start new workers in place of a pool that a dead one broke (its futures stay failed)."""
        processes = list((getattr(self.executor, "_processes", None) or {}).values())  # private, as stop_pool
        stop_pool(self.executor, abandon=True)
        died = (f"a generate worker died ({_how_ended(processes)}) with attempts {attempts.start}-{attempts.stop - 1} "
                "in flight")
        if not self.restarts:
            raise FetchError(f"{died}, after {RESTARTS} restarts; the demos saved so far are valid: run the same "
                             "command again to continue") from error
        self.restarts -= 1
        print(f"{died}; starting new workers to make them again ({self.restarts} more restart(s) allowed)",
              file=sys.stderr, flush=True)
        self.executor = self._start()

    def close(self) -> None:
        stop_pool(self.executor, abandon=True)  # the chunks still in flight are not wanted


def _how_ended(processes: list[multiprocessing.process.BaseProcess]) -> str:
    """How a broken pool's workers ended, but for those the pool itself then terminated (SIGTERM):
    "SIGKILL" (`kill -9`, the out-of-memory killer), "SIGSEGV", "exit status 1"."""
    # The pool's own thread may be reaping a worker at this moment: until it has stored the exit status,
    # the worker's `exitcode` reads None (its waitpid here finds nothing left to wait for). CI's non-root
    # run caught that once ("how, unknown" for a SIGKILL).
    deadline = time.monotonic() + 2.0
    while any(p.exitcode is None for p in processes) and time.monotonic() < deadline:
        time.sleep(0.01)
    ends = {p.exitcode for p in processes if p.exitcode is not None} - {-signal.SIGTERM}
    if not ends:
        return "how, unknown"
    names = {int(s): s.name for s in signal.Signals}
    return ", ".join(names.get(-c, f"signal {-c}") if c < 0 else f"exit status {c}" for c in sorted(ends))


class RayCluster:
    """Attempts as calls on Ray actors, one per CPU of the cluster (or `workers`), each holding one
    env. `address`: a running cluster's ("auto", "ray://head:10001"); None starts a local Ray."""

    def __init__(self, work: Work, address: str | None, workers: int | None = None) -> None:
        try:
            import ray
        except ImportError as e:
            raise FetchError(f"--ray needs Ray: {install_hint('ray')}") from e
        self.ray = ray
        self.started = not ray.is_initialized()
        if self.started:
            try:
                ray.init(address=address, log_to_driver=False, include_dashboard=False)
            except (ConnectionError, RuntimeError, ValueError) as e:
                first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
                raise FetchError(f"cannot join the Ray cluster at {address or 'a new local instance'} ({first}); "
                                 "start one (`ray start --head`) or pass --ray local") from e
        self.workers = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        actor = ray.remote(num_cpus=1)(_RayWorker)
        shared = ray.put(work)
        self.actors = [actor.remote(shared) for _ in range(self.workers)]
        self._next = itertools.cycle(self.actors)

    def results(self, first: int) -> Iterator[Result]:
        return _ordered(lambda start, n: next(self._next).run.remote(start, n),
                        lambda ref: self.ray.get(ref), self.workers, first)

    def close(self) -> None:
        for a in self.actors:
            self.ray.kill(a)
        if self.started:
            self.ray.shutdown()


class _RayWorker:
    def __init__(self, work: Work) -> None:
        _one_gl_thread()
        self.generator = work.generator()

    def run(self, first: int, count: int) -> list[Result]:
        return [self.generator.attempt(n) for n in range(first, first + count)]
