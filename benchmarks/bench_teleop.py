"""Benchmark the collection loop's timing with the viewer window on (run it under a display or Xvfb):

    xvfb-run -a -s "-screen 0 1024x768x24" env -u MUJOCO_GL python -m benchmarks.bench_teleop [--env PickPlace-v2]

MUJOCO_GL unset: MuJoCo renders through the display's GL, as on a desktop. The expert drives (a person's
device is polled the same way), once with the window's shadows and once without (`--shadows on,off`; kept
whatever the frame times, `frame_budget=None`); the table gives, for each, how late each control tick started
after its deadline, the time from reading the input to the action having been applied, the gap between one
attempt's last step and the next attempt's first, the frames the viewer showed, and what the viewer costs the
control thread each tick.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from typing import Any

import numpy as np

from benchmarks._machine import machine_line
from fetch.teleop.expert import ExpertDevice
from fetch.teleop.gamepad import KIND as GAMEPAD
from fetch.teleop.session import CollectConfig, HudState, Session, make_env
from fetch.teleop.viewer import Viewer


class TimedViewer(Viewer):
    """The viewer, with the time each `show` took on the control thread."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.costs: list[float] = []

    def show(self, hud: HudState) -> None:
        start = time.perf_counter()
        super().show(hud)
        self.costs.append(time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="PickPlace-v2")
    parser.add_argument("--demos", type=int, default=20)
    parser.add_argument("--hz", type=float, default=None, help="control rate (default: the env's, 25 Hz)")
    parser.add_argument("--shadows", default="on,off", help="the runs: on, off or both (default on,off)")
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    runs = {}
    for shadows in args.shadows.split(","):
        with tempfile.TemporaryDirectory() as out:
            config = CollectConfig(env_id=args.env, out=out, episodes=args.demos, device="expert", render="human",
                                   control_hz=args.hz, stop_on_success=True, max_steps=500)
            env = make_env(config)
            viewer = TimedViewer(env, GAMEPAD.legend, shadows=shadows == "on", frame_budget=None)
            session = Session(config, ExpertDevice(env), env=env, display=viewer, log=lambda text: None)
            summary = session.run()
        runs[shadows] = (session, summary, viewer)
    period = next(iter(runs.values()))[0].clock.period
    print(machine_line())
    print(f"load average {load_before:.1f} before the runs; {args.env}, {1 / period:.0f} Hz, window 640x480 "
          "with the wrist inset, "
          f"{args.demos} demos a run\n")
    columns = {shadows: measures(session, summary, viewer) for shadows, (session, summary, viewer) in runs.items()}
    names = list(next(iter(columns.values())))
    print("| measure | " + " | ".join(f"shadows {s}: p50 / p99 / max" for s in columns) + " | target |")
    print("|---|" + "---|" * len(columns) + "---|")
    targets = {"tick start after its deadline [ms]": "p99 < 2", "achieved control rate [Hz]": f"{1 / period:.0f}",
               "gap between attempts (last step -> next first input) [ms]": f"<= {period * 1e3:.0f}"}
    for name in names:
        cells = []
        for column in columns.values():
            values = column[name]
            cells.append(f"{values[0]:.2f}" if len(values) == 1 else " / ".join(f"{v:.2f}" for v in values))
        print(f"| {name} | " + " | ".join(cells) + f" | {targets.get(name, '')} |")


def measures(session: Session, summary: Any, viewer: TimedViewer) -> dict[str, list[float]]:
    """Each row's p50, p99 and max (or its one value) for one run."""
    ticks = np.array(session.ticks)
    late = (ticks[:, 1] - ticks[:, 0]) * 1e3
    applied = (ticks[:, 2] - ticks[:, 1]) * 1e3
    bounds = np.cumsum([a.steps for a in summary.attempts])[:-1]
    gaps = np.array([(ticks[b, 1] - ticks[b - 1, 2]) * 1e3 for b in bounds])
    seconds = ticks[-1, 2] - ticks[0, 0]

    def spread(values: np.ndarray) -> list[float]:
        return [float(np.percentile(values, 50)), float(np.percentile(values, 99)), float(values.max())]

    return {
        "tick start after its deadline [ms]": spread(late),
        "input read -> action applied (env.step returned) [ms]": spread(applied),
        "gap between attempts (last step -> next first input) [ms]": spread(gaps),
        "viewer's time on the control thread per tick [ms]": spread(np.array(viewer.costs) * 1e3),
        "achieved control rate [Hz]": [summary.achieved_hz],
        "frames shown per second": [viewer.frames / seconds],
    }

if __name__ == "__main__":
    main()
