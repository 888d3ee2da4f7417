"""Worker processes that end with the process that started them."""

from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing.connection
import multiprocessing.process
import os
import signal
import threading
import time
from collections.abc import Iterator

from fetch.stopping import stops_deferred


def exit_with_parent(parent: int, period: float = 0.5) -> None:
    """End this worker once its parent is gone: a SIGKILLed parent runs no shutdown, and its workers
    would stay, stuck writing to a dead pipe or waiting for work (~136-276 MB each, forever). A watch
    on the parent's pid, not PR_SET_PDEATHSIG: that fires when the *thread* that started the worker
    ends, and a writer's thread starts some of them."""
    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(period)
        os._exit(1)

    threading.Thread(target=watch, name="fetch-exit-with-parent", daemon=True).start()


@contextlib.contextmanager
def workers_deaf_to_ctrl_c() -> Iterator[None]:
    """Around whatever may start a pool's workers (a submit): SIGINT blocked in this thread, so that
    the workers start with it blocked (a signal mask survives fork and exec) until `start_worker`
    ignores it; a Ctrl-C while a worker imports would otherwise end it with a traceback. A stop is only
    delayed (`stops_deferred`): raised between a worker's start and the pool recording it, it left that
    worker out of the pool, running on after the tool had exited."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        with stops_deferred():
            yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def start_worker(parent: int) -> None:
    """What a pool's worker does first: end with its parent (`exit_with_parent`), and leave Ctrl-C to
    it. A terminal's Ctrl-C goes to the whole process group; a worker that raised it mid-job sent a
    KeyboardInterrupt back through its job's future, which ended the collector's writer thread, and
    the collector waited for it forever. The parent stops its workers when it stops."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked by workers_deaf_to_ctrl_c
    exit_with_parent(parent)


def stop_pool(pool: concurrent.futures.ProcessPoolExecutor, abandon: bool) -> None:
    """Shut a pool of workers down; with `abandon` (jobs still running whose results are not wanted),
    terminate its workers rather than wait for them. A worker that finishes a job while the pool
    shuts down writes its result to a pipe that nothing reads any more, and waits there for good, and
    so does the interpreter's exit, which joins it (a double Ctrl-C hung `render-obs` and `generate`).
    A second stop while waiting for the workers to finish ends them as abandoned: left starting, one
    read the pool's semaphores after the exit had removed them, and died with a traceback (CI, a
    double Ctrl-C in `export --to lerobot`).

    Cancel a pool's futures only this way (`cancel_futures`: the pool's own thread cancels them). On
    CPython 3.11, a future cancelled from outside that the pool's thread has not yet seen when the pool
    breaks (its workers terminated here, or one died) ends that thread with InvalidStateError, a traceback
    on stderr, before it terminates the other workers (a Ctrl-C in `render-obs`, in CI; CPython gh-107219,
    fixed upstream in 2023 but not in 3.11.7)."""
    if not abandon:
        try:
            pool.shutdown(wait=True, cancel_futures=True)
            return
        except BaseException:
            _end_workers(pool)
            raise
    _end_workers(pool)


def _end_workers(pool: concurrent.futures.ProcessPoolExecutor) -> None:
    """Terminate a pool's workers, and wait for them and for the pool's own thread. That thread closes
    its wake-up pipe as it ends, and the interpreter's exit writes to that pipe unless the thread has
    ended: the two at once failed on the closed pipe ("Exception ignored ... Bad file descriptor")."""
    with stops_deferred():  # a stop raised in the middle would leave the rest running after the tool exits
        workers = list((getattr(pool, "_processes", None) or {}).values())  # private: CPython 3.8-3.13
        results = getattr(pool, "_result_queue", None)  # private too; shutdown lets go of it
        manager = getattr(pool, "_executor_manager_thread", None)  # private too
        pool.shutdown(wait=False, cancel_futures=True)
        for worker in workers:
            worker.terminate()
        for worker in workers:
            worker.join(timeout=5)
        if results is not None and all_ended(workers):
            # A worker terminated while it wrote a result leaves half a message in the pipe, and the
            # pool's thread waits for the rest for good (the interpreter's exit with it: `generate`
            # hung once after its last demo). This end closed too, with every worker gone, it reads
            # the end of the pipe instead.
            results._writer.close()
        if manager is not None and manager is not threading.current_thread():
            manager.join(timeout=5)


def all_ended(workers: list[multiprocessing.process.BaseProcess]) -> bool:
    """Whether every one of `workers` has ended, read from their sentinels. Not `is_alive`: a worker
    that the pool's own thread reaped first looks alive to it for good (its `waitpid` fails with ECHILD,
    and the exit code stays unknown)."""
    sentinels = []
    for worker in workers:
        try:
            sentinels.append(worker.sentinel)
        except ValueError:  # closed: joined and released, so ended
            continue
    return len(multiprocessing.connection.wait(sentinels, timeout=0)) == len(sentinels)


def usable_cores() -> int:
    """The cores this process may run on (its affinity where the OS has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
