"""A collector stopped by a signal: SIGTERM as Ctrl-C, saves finished, summary printed, exit 128 + signal."""

from __future__ import annotations

import pathlib
import signal
import subprocess
import sys

import pytest

from fetch.dataset import open_dataset, validate
from fetch.errors import DatasetError

SCRIPTS = pathlib.Path(__file__).parent / "scripts"


def collector(out: pathlib.Path, *extra: str) -> list[str]:
    return [sys.executable, "-u", "-m", "fetch.cli", "collect", "--env", "Reach-v2", "--render", "none",
            "--out", str(out), *extra]


def saved_names(text: str) -> set[str]:
    return {line.split()[1].rstrip(":") for line in text.splitlines() if line.startswith("saved demo_")}


def _stop_after_saves(out: pathlib.Path, signals: tuple[signal.Signals, ...], saves: int = 3,
                      gap: float = 0.0) -> tuple[int, str, str]:
    proc = subprocess.Popen(collector(out, "--device", "expert", "--episodes", "100000", "--control-hz", "200"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    seen, head = 0, []
    for line in proc.stdout:
        head.append(line)
        seen += line.startswith("saved ")
        if seen >= saves:
            break
    for i, sig in enumerate(signals):
        if i:
            subprocess.run(["sleep", str(gap)])
        proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=60)
    return proc.returncode, "".join(head) + stdout, stderr


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_stop_signal_finishes_the_saves_and_prints_the_summary(tmp_path: pathlib.Path,
                                                                  sig: signal.Signals) -> None:
    out = tmp_path / "demos"
    code, stdout, stderr = _stop_after_saves(out, (sig,))
    assert code == 128 + sig, (code, stderr[-500:])
    assert f"interrupted ({sig.name}): finishing the saves" in stdout + stderr
    summary = [line for line in stdout.splitlines() if " attempts, " in line]
    assert summary, stdout[-500:]
    saved_this_session = int(summary[-1].split(" saved this session")[0].rsplit(" ", 1)[1])
    with open_dataset(out) as ds:
        assert validate(ds) == []
        assert saved_names(stdout) <= set(ds.demo_names)
        assert len(ds.demo_names) == saved_this_session >= 3


def test_a_second_ctrl_c_does_not_abandon_the_saves(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "demos"
    code, stdout, stderr = _stop_after_saves(out, (signal.SIGINT, signal.SIGINT), gap=0.005)
    summary = [line for line in stdout.splitlines() if " attempts, " in line]
    assert summary, (code, stdout[-500:], stderr[-500:])
    # 130, or killed by the second SIGINT when it lands after the summary, while the interpreter
    # shuts down (Python then restores the default handler): nothing is left to lose by then.
    assert code in (130, -signal.SIGINT), (code, stderr[-500:])
    assert "Traceback" not in stderr
    with open_dataset(out) as ds:
        assert validate(ds) == []
        assert saved_names(stdout) <= set(ds.demo_names)


def test_a_headless_gamepad_session_stops_on_sigterm(tmp_path: pathlib.Path) -> None:
    """SDL turns SIGTERM into a quit event when its video subsystem starts; nothing reads it in a
    headless session, so `kill PID` did nothing. The collector's own handler must win."""
    pytest.importorskip("pygame")
    proc = subprocess.Popen([sys.executable, "-u", str(SCRIPTS / "pad_session.py"), str(tmp_path / "demos")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    for line in proc.stderr:  # the collector says so once its session is built and about to run
        if line.startswith("collecting "):
            break
    subprocess.run(["sleep", "1"])  # into its first attempt (500 steps at 25 Hz)
    proc.send_signal(signal.SIGTERM)
    try:
        stdout, stderr = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail("the gamepad session ignored SIGTERM")
    assert proc.returncode == 128 + signal.SIGTERM, stderr[-800:]
    assert " attempts, " in stdout


@pytest.mark.parametrize("seed", ["-5", str(2**64)])
def test_seeds_out_of_range_are_refused_before_anything_is_written(tmp_path: pathlib.Path, seed: str) -> None:
    out = tmp_path / "demos"
    run = subprocess.run(collector(out, "--device", "expert", "--episodes", "1", "--seed", seed),
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stderr
    assert "--seed" in run.stderr and "Traceback" not in run.stderr
    assert not out.exists()


# CPython turns a stop raised inside a C extension's call (h5py's attribute iteration, in a CI run of
# export-lerobot) into this SystemError, with the stop as its context.
EXTENSION_ERROR = "<cyfunction FastRLock.__exit__ at 0x7fd2020be140> returned a result with an exception set"


@pytest.mark.parametrize("then", [BrokenPipeError, lambda: DatasetError("a render worker died"),
                                  lambda: SystemError(EXTENSION_ERROR)], ids=["pipe", "fetch-error", "extension"])
def test_an_error_while_winding_down_after_a_stop_still_exits_as_the_stop(then, capsys) -> None:  # noqa: ANN001
    """A Ctrl-C during an export's rendering can break a pipe to a worker (or kill one) while the
    work is wound down, or land inside a C extension that reports it as its own SystemError; the exit
    status is the stop's, 130, not a pipe's 1, an error's 2 or a traceback."""
    import argparse

    from fetch.cli import run_stoppable

    def run(_: argparse.Namespace) -> int:
        try:
            raise KeyboardInterrupt
        finally:
            raise then()

    assert run_stoppable(lambda: argparse.Namespace(run=run, command="export")) == 130
    err = capsys.readouterr().err
    assert err == "" or err.startswith("gym-fetch export: error: a render worker died")


def test_an_extension_error_with_no_stop_behind_it_is_not_taken_for_one() -> None:
    import argparse

    from fetch.cli import run_stoppable

    def run(_: argparse.Namespace) -> int:
        raise SystemError(EXTENSION_ERROR)

    with pytest.raises(SystemError, match="FastRLock"):
        run_stoppable(lambda: argparse.Namespace(run=run, command="export"))


SWALLOWED_STOP = """
import os, pathlib, signal, sys, weakref
from fetch.dataset.dirs import replacing_dir
from fetch.stopping import Stopped, stop_on_signals

target = pathlib.Path(sys.argv[1])

class Thing:
    pass

with stop_on_signals():
    try:
        with replacing_dir(target, force=True) as building:
            (building / "new").write_text("new")
            thing = Thing()
            # Ctrl-C lands while a weakref callback runs: Python prints the handler's exception as
            # "Exception ignored in ..." and carries on, as it did in a LeRobot export in CI.
            ref = weakref.ref(thing, lambda _: os.kill(os.getpid(), signal.SIGINT))
            del thing
            (building / "more").write_text("the work went on")
    except Stopped as e:
        print("stopped", e.signum)
"""


def test_a_stop_in_a_weakref_callback_is_not_swallowed_and_keeps_the_old_directory(tmp_path: pathlib.Path) -> None:
    target = tmp_path / "ds"
    target.mkdir()
    (target / "old").write_text("old")
    proc = subprocess.run([sys.executable, "-c", SWALLOWED_STOP, str(target)], capture_output=True, text=True,
                          timeout=60)
    assert "Exception ignored in" not in proc.stderr  # delivered again once out of the callback
    assert proc.stdout.strip() == f"stopped {int(signal.SIGINT)}", proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
    assert [p.name for p in target.iterdir()] == ["old"]


def test_a_stop_while_the_handlers_are_put_back_is_still_the_exit_status(monkeypatch) -> None:  # noqa: ANN001
    """A SIGTERM that lands as the command winds down (its signal handlers and environment being put
    back) ended `view` with a traceback in the soak; it is the exit status instead."""
    import contextlib
    import os
    import time

    from fetch import cli, stopping

    @contextlib.contextmanager
    def environ(**_: object):  # noqa: ANN202
        yield
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)  # the handler runs here, in the teardown

    monkeypatch.setattr(stopping, "environ", environ)
    before = {s: signal.getsignal(s) for s in stopping.STOP_SIGNALS}
    try:
        assert cli.main(["info", "/nonexistent/demos"]) == 128 + signal.SIGTERM  # not a traceback, not 2
        stopping.raise_if_stopped()  # outside the command: its stop is not the caller's
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def test_a_dropped_stop_is_not_sent_again_once_the_tool_has_left() -> None:
    """`_dropped` sends a swallowed stop again 20 ms later; a tool that has left `stop_on_signals` by then (it
    acted on the stop another way) gets no signal in its exit's own code, where it was printed as an ignored
    exception in an atexit callback."""
    import time
    import types

    from fetch import stopping

    received: list[int] = []
    with stopping.stop_on_signals():
        stopping._dropped(types.SimpleNamespace(exc_value=stopping.Stopped(signal.SIGINT)))
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        time.sleep(0.3)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert received == []


def _sleep(seconds: float) -> float:
    import time

    time.sleep(seconds)
    return seconds


def test_a_stop_while_a_pool_is_being_stopped_waits_until_every_worker_is() -> None:
    """`stop_pool` terminates and joins its workers with stops deferred (`stops_deferred`): a second Ctrl-C
    raised inside that loop would leave the workers after it running on (and a spawned one still
    starting then fails with a traceback once the tool has exited). The stop comes out once they are all
    gone; its handler raises it then, as it would have."""
    import concurrent.futures
    import multiprocessing
    import os
    import time

    from fetch._processes import stop_pool
    from fetch.stopping import Stopped, stop_on_signals
    from procs import alive

    pool = concurrent.futures.ProcessPoolExecutor(3, mp_context=multiprocessing.get_context("spawn"))
    futures = [pool.submit(_sleep, 30.0) for _ in range(3)]
    deadline = time.monotonic() + 60
    while len(pool._processes or {}) < 3 or not all(f.running() for f in futures):
        assert time.monotonic() < deadline, "the pool's workers did not start"
        time.sleep(0.05)
    workers = list(pool._processes.values())
    terminate = type(workers[0]).terminate

    def terminate_and_stop(self) -> None:  # noqa: ANN001
        terminate(self)
        if self is workers[0]:
            os.kill(os.getpid(), signal.SIGINT)  # a Ctrl-C while the first worker is being stopped
            time.sleep(0.05)  # the handler would raise here, with two workers still to stop

    before = signal.getsignal(signal.SIGINT)
    try:
        with stop_on_signals():
            type(workers[0]).terminate = terminate_and_stop  # type: ignore[method-assign]
            try:
                with pytest.raises(Stopped):
                    stop_pool(pool, abandon=True)
            finally:
                type(workers[0]).terminate = terminate  # type: ignore[method-assign]
            # /proc, not `is_alive`: the pool's own thread may reap a worker first, and `is_alive` then says True
            assert [alive(w.pid) for w in workers] == [False, False, False]
    finally:
        signal.signal(signal.SIGINT, before)



def test_a_stop_while_waiting_for_a_pools_workers_to_finish_ends_them() -> None:
    """`stop_pool` without `abandon` waits for the workers to finish what they run; a second Ctrl-C during
    that wait left them running after the tool had exited, and one still starting then read the pool's
    semaphores that the exit had removed, and died with a traceback (CI, `export --to lerobot`). The stop
    comes out with the workers, and the pool's own thread, ended."""
    import concurrent.futures
    import multiprocessing
    import os
    import threading
    import time

    from fetch._processes import stop_pool
    from fetch.stopping import Stopped, stop_on_signals
    from procs import alive

    pool = concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
    future = pool.submit(_sleep, 30.0)
    deadline = time.monotonic() + 60
    while not future.running():
        assert time.monotonic() < deadline, "the pool's worker did not start"
        time.sleep(0.05)
    workers, manager = list(pool._processes.values()), pool._executor_manager_thread
    before = signal.getsignal(signal.SIGINT)
    try:
        with stop_on_signals():
            timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))  # a Ctrl-C while it waits
            timer.start()
            start = time.monotonic()
            with pytest.raises(Stopped):
                stop_pool(pool, abandon=False)
            assert time.monotonic() - start < 15  # not the job's 30 s
            assert [alive(w.pid) for w in workers] == [False]
            assert manager is not None and not manager.is_alive()
    finally:
        signal.signal(signal.SIGINT, before)
        for worker in workers:
            worker.kill()


def test_a_worker_reaped_by_another_thread_counts_as_ended() -> None:
    """`stop_pool` closes its result pipe's writing end only once every worker has ended (`all_ended`).
    When two threads wait for one worker (the pool's own thread and `stop_pool`), the one whose `waitpid`
    loses gets ECHILD, and `is_alive` says True until the other records the exit code; the sentinel says
    it ended. Here the worker is reaped behind its Process object's back, so `is_alive` stays wrong."""
    import multiprocessing
    import os

    from fetch._processes import all_ended

    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_sleep, args=(30.0,)) for _ in range(2)]
    for worker in workers:
        worker.start()
    try:
        os.kill(workers[0].pid, signal.SIGKILL)
        os.waitpid(workers[0].pid, 0)
        assert workers[0].is_alive()  # what the guard used to read
        assert all_ended(workers[:1])
        assert not all_ended(workers)  # the other one still runs
        workers[1].terminate()
        workers[1].join(timeout=30)
        assert all_ended(workers)
    finally:
        for worker in workers[1:]:
            worker.kill()
