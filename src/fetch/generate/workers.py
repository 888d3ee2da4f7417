"""Where attempts run: in this process, in a pool of processes, or as Ray actors on a cluster.

Every backend yields results in attempt order (attempt n always resets with seed + n and draws
from its own random stream), so what is kept does not depend on how many workers made it.
Attempts go out in chunks; a bounded window of chunks is in flight, the oldest awaited first.
"""

from __future__ import annotations

import collections
import concurrent.futures
import dataclasses
import itertools
import multiprocessing
import os
from collections.abc import Iterator
from typing import Any, Protocol

from fetch._processes import start_worker, stop_pool, workers_deaf_to_ctrl_c
from fetch.errors import FetchError, install_hint
from fetch.generate.attempt import Generator, Options, Result
from fetch.generate.sources import Sources

CHUNK = 4
"""Attempts per task sent to a worker."""
WINDOW = 3
"""Chunks in flight per worker: enough to keep it busy while the oldest is awaited."""


@dataclasses.dataclass(frozen=True)
class Work:
    """What every worker needs to make any attempt (pickled once per worker)."""

    sources: Sources
    options: Options
    seed: int

    def generator(self) -> Generator:
        s = self.sources
        return Generator(s.env_id, s.env_kwargs, s.segments, self.options, self.seed)


class Backend(Protocol):
    workers: int

    def results(self, first: int) -> Iterator[Result]:
        """Attempts first, first + 1, ... in order, for as long as the caller iterates."""

    def close(self) -> None: ...


def default_workers() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


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
    _worker = work.generator()


def _run_chunk(first: int, count: int) -> list[Result]:
    assert _worker is not None
    return [_worker.attempt(n) for n in range(first, first + count)]


def _ordered(submit: Any, wait: Any, workers: int, first: int) -> Iterator[Result]:
    """Keep WINDOW chunks per worker in flight; yield their results oldest chunk first."""
    pending: collections.deque[Any] = collections.deque()
    starts = itertools.count(first, CHUNK)
    while True:
        while len(pending) < WINDOW * workers:
            pending.append(submit(next(starts), CHUNK))
        yield from wait(pending.popleft())


class Pool:
    """Attempts in `workers` processes (spawned: no threads or GL state inherited)."""

    def __init__(self, work: Work, workers: int, nice: int = 0) -> None:
        self.workers = workers
        self.executor = concurrent.futures.ProcessPoolExecutor(
            workers, mp_context=multiprocessing.get_context("spawn"), initializer=_init_worker,
            initargs=(work, nice, os.getpid()))

    def results(self, first: int) -> Iterator[Result]:
        return _ordered(self._submit, lambda future: future.result(), self.workers, first)

    def _submit(self, start: int, n: int) -> concurrent.futures.Future[list[Result]]:
        with workers_deaf_to_ctrl_c():
            return self.executor.submit(_run_chunk, start, n)

    def close(self) -> None:
        stop_pool(self.executor, abandon=True)  # the chunks still in flight are not wanted


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
        self.generator = work.generator()

    def run(self, first: int, count: int) -> list[Result]:
        return [self.generator.attempt(n) for n in range(first, first + count)]
