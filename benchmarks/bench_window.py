"""Benchmark the collection window's frame rate and input-to-picture latency, alone and beside generation:

    xvfb-run -a -s "-screen 0 1024x768x24" env -u MUJOCO_GL python -m benchmarks.bench_window [--seconds 20]

MUJOCO_GL unset: MuJoCo renders through the display's GL, as on a desktop (under Xvfb: llvmpipe, software
GL). The expert drives the window at its default size at 25 Hz, once with nothing else running ("alone") and
once beside a real `gym-fetch generate --workers 2` (started in a session of its own, as from another
terminal, on a source dataset the expert makes here with `collect --render none`; stopped with Ctrl-C's
signal after the run). Each condition runs once per window setting (`--windows`): `default`, the window as
`gym-fetch collect` opens it (it chooses what to draw from its measured frame times), and `full`, shadows and
inset always on.

Latency is measured end to end: every tick's scene is posted tagged with its tick, the time its newest
applied input was read is kept per tick, and for each frame flipped onto the window the latency is the flip
time minus the read time of the newest input the drawn scene includes. Frames shown per second are counted
in 1 s windows; frame time is the render thread's time per frame shown (wall clock).
"""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any, NamedTuple

import numpy as np

from benchmarks._machine import machine_line
from fetch.teleop.devices import Command
from fetch.teleop.expert import ExpertDevice
from fetch.teleop.gamepad import KIND as GAMEPAD
from fetch.teleop.session import CollectConfig, HudState, Session, make_env
from fetch.teleop.viewer import Viewer

WINDOWS = {"default": {}, "full": {"frame_budget": None}}
"""The window settings a run can use: `Viewer` keyword arguments."""


class StampedViewer(Viewer):
    """The viewer, noting for each tick when the newest input its scene includes was read, and for each frame
    it flips when that was and which tick's scene the frame drew."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.session: Session | None = None
        self.read: dict[int, float] = {}
        """Tick -> when the newest input in the scene posted then was read [s, perf_counter] (none after a reset:
        that scene holds no input)."""
        self.flips: list[tuple[float, int, float]] = []
        """Per frame shown: its flip time [s, perf_counter], the tick it drew, its render time [s]."""

    def show(self, hud: HudState) -> None:
        assert self.session is not None
        if hud.step > 0:  # the scene holds this attempt's steps, the last of them the newest input's
            self.read[self.ticks + 1] = self.session.ticks[-1][1]
        before = self.frames
        super().show(hud)
        if self.frames > before:
            self.flips.append((time.perf_counter(), self.shown_frame.tag, self.shown_frame.seconds))


class Until:
    """A device that drives with `device` until `end` [s, perf_counter], then quits the session."""

    name = "expert"

    def __init__(self, device: ExpertDevice, end: float) -> None:
        self.device, self.end = device, end

    def reset(self) -> None:
        self.device.reset()

    def poll(self, obs: Any) -> Command:
        if time.perf_counter() >= self.end:
            return Command(np.zeros(4, np.float32), quit=True)
        return self.device.poll(obs)

    def close(self) -> None:
        self.device.close()


class Run(NamedTuple):
    """One condition's measures."""

    fps: tuple[float, float]
    """Frames shown per 1 s window: median, p10."""
    frame_ms: tuple[float, float]
    """Render time per frame shown [ms]: p50, p90."""
    latency_ms: tuple[float, float]
    """Input read -> a frame including it flipped [ms]: p50, p90."""
    control_hz: float
    settings: str
    """What the window drew at the end: shadows and inset on or off, and what its HUD said."""
    load: float
    """The 1-minute load average at the end."""


def run_window(env_id: str, seconds: float, window: str, out: pathlib.Path) -> Run:
    """The expert drives `env_id` with the window for `seconds` [s]; the window's measures."""
    config = CollectConfig(env_id=env_id, out=str(out), episodes=0, device="expert", render="human",
                           stop_on_success=True, max_steps=500)
    env = make_env(config)
    viewer = StampedViewer(env, GAMEPAD.legend, **WINDOWS[window])
    start = time.perf_counter()
    session = Session(config, Until(ExpertDevice(env), start + seconds), env=env, display=viewer,
                      log=lambda text: None)
    viewer.session = session
    summary = session.run()
    if summary.error:
        raise RuntimeError(summary.error)
    flips = np.array(viewer.flips)
    times = flips[:, 0]
    settle = times[0] + 1.0  # the window's first second: the GL context warming up, the first frames judged
    kept = flips[times >= settle]
    bins = np.floor(kept[:, 0] - settle).astype(int)
    per_second = np.bincount(bins)[:-1] if len(bins) else np.zeros(1)  # the last second is cut short
    latency = [(flip - viewer.read[int(tick)]) * 1e3 for flip, tick, _ in kept if int(tick) in viewer.read]
    render = kept[:, 2] * 1e3
    settings = (f"shadows {'on' if viewer.shadows else 'off'}, inset {'on' if viewer.inset_on else 'off'}"
                + (f" (HUD: \"{viewer.economy}\")" if viewer.economy else ""))
    return Run((float(np.median(per_second)), float(np.percentile(per_second, 10))),
               (float(np.percentile(render, 50)), float(np.percentile(render, 90))),
               (float(np.percentile(latency, 50)), float(np.percentile(latency, 90))),
               summary.achieved_hz, settings, os.getloadavg()[0])


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "fetch.cli", *args]


def start_generate(env_id: str, root: pathlib.Path, warmup: float) -> subprocess.Popen[bytes]:
    """`gym-fetch generate --workers 2` from a small expert-made source, in a session of its own (as from
    another terminal), given `warmup` [s] to start its workers."""
    source = root / "source"
    if not source.exists():
        subprocess.run(cli("collect", "--env", env_id, "--device", "expert", "--render", "none", "--episodes", "10",
                           "--out", str(source)), check=True, capture_output=True)
    quiet = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MUJOCO_GL")}
    proc = subprocess.Popen(cli("generate", "--source", str(source), "--out", str(root / "generated"),
                                "--demos", "100000", "--workers", "2"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True, env=quiet)
    time.sleep(warmup)
    if proc.poll() is not None:
        raise RuntimeError(f"gym-fetch generate ended early: {proc.stderr.read().decode()[-2000:]}"
                           if proc.stderr else "gym-fetch generate ended early")
    return proc


def stop(proc: subprocess.Popen[bytes]) -> None:
    """Stop generation as Ctrl-C would (its whole session), then for good if it has not ended in 30 s."""
    try:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    except ProcessLookupError:
        pass


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="PickPlace-v2")
    parser.add_argument("--seconds", type=float, default=20.0, help="per run (default 20)")
    parser.add_argument("--windows", default="default,full", help=f"window settings, of {', '.join(WINDOWS)}")
    parser.add_argument("--conditions", default="alone,beside", help="alone, beside (gym-fetch generate) or both")
    parser.add_argument("--warmup", type=float, default=10.0, help="[s] for generate's workers to start")
    args = parser.parse_args()
    windows = args.windows.split(",")
    for name in windows:
        if name not in WINDOWS:
            parser.error(f"unknown window setting {name!r}; known: {', '.join(WINDOWS)}")
    load_before = os.getloadavg()
    runs: dict[tuple[str, str], Run] = {}
    with tempfile.TemporaryDirectory(prefix="bench-window-") as tmp:
        root = pathlib.Path(tmp)
        for condition in args.conditions.split(","):
            generate = start_generate(args.env, root, args.warmup) if condition == "beside" else None
            try:
                for window in windows:
                    runs[condition, window] = run_window(args.env, args.seconds, window, root / f"{condition}-{window}")
            finally:
                if generate is not None:
                    stop(generate)
    print(machine_line("pygame-ce"))
    print(f"load average {' '.join(f'{x:.2f}' for x in load_before)} before the runs; {args.env}, window 640x480, "
          f"{args.seconds:.0f} s a run\n")
    print("| condition | window | frames/s shown: median / p10 | frame time [ms]: p50 / p90 | "
          "input -> picture [ms]: p50 / p90 | control rate [Hz] | what it drew | load (1 min) after |")
    print("|---|---|---|---|---|---|---|---|")
    names = {"alone": "alone", "beside": "beside `gym-fetch generate --workers 2`"}
    for (condition, window), run in runs.items():
        print(f"| {names[condition]} | {window} | {fmt(run.fps, 0)} | {fmt(run.frame_ms)} | {fmt(run.latency_ms)} "
              f"| {run.control_hz:.2f} | {run.settings} | {run.load:.2f} |")


def fmt(values: tuple[float, float], digits: int = 1) -> str:
    return " / ".join("n/a" if math.isnan(v) else f"{v:.{digits}f}" for v in values)


if __name__ == "__main__":
    main()
