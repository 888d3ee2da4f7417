"""Benchmark the collection loop's timing with the viewer window on (run it under a display or Xvfb):

    xvfb-run -a -s "-screen 0 1024x768x24" env -u MUJOCO_GL python benchmarks/bench_teleop.py [--env PickPlace-v2]

MUJOCO_GL unset: MuJoCo renders through the display's GL, as on a desktop. The expert drives (a person's
device is polled the same way); the table gives how late each control tick started after its deadline, the time
from reading the input to the action having been applied, the gap between one attempt's last step and the next
attempt's first, the frames the viewer showed, and what the viewer costs the control thread each tick.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import mujoco
import numpy as np

import fetch
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
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as out:
        config = CollectConfig(env_id=args.env, out=out, episodes=args.demos, device="expert", render="human",
                               control_hz=args.hz)
        env = make_env(config)
        viewer = TimedViewer(env, GAMEPAD.legend)
        session = Session(config, ExpertDevice(env), env=env, display=viewer, log=lambda text: None)
        summary = session.run()
    period = session.clock.period
    ticks = np.array(session.ticks)
    late = (ticks[:, 1] - ticks[:, 0]) * 1e3
    applied = (ticks[:, 2] - ticks[:, 1]) * 1e3
    bounds = np.cumsum([a.steps for a in summary.attempts])[:-1]
    gaps = np.array([(ticks[b, 1] - ticks[b - 1, 2]) * 1e3 for b in bounds])
    seconds = ticks[-1, 2] - ticks[0, 0]
    print(f"machine: {platform.platform()}, {os.cpu_count()} cores, load average {load_before:.1f} before and "
          f"{os.getloadavg()[0]:.1f} after; python {platform.python_version()}, fetch {fetch.__version__}, "
          f"mujoco {mujoco.__version__}; {args.env}, {1 / period:.0f} Hz, window 640x480, {len(ticks)} ticks, "
          f"{len(summary.attempts)} attempts, {viewer.frames} frames shown\n")
    rows = [
        ("tick start after its deadline [ms]", late, "p99 < 2"),
        ("input read -> action applied (env.step returned) [ms]", applied, ""),
        ("input-to-action latency, worst case = period + the above [ms]", applied + period * 1e3,
         f"<= {period * 1e3:.0f} + step"),
        ("gap between attempts (last step -> next first input) [ms]", gaps, f"<= {period * 1e3:.0f}"),
        ("viewer's time on the control thread per tick [ms]", np.array(viewer.costs) * 1e3, ""),
    ]
    print("| measure | p50 | p99 | max | target |\n|---|---|---|---|---|")
    for name, values, target in rows:
        print(f"| {name} | {np.percentile(values, 50):.2f} | {np.percentile(values, 99):.2f} | "
              f"{values.max():.2f} | {target} |")
    print(f"| achieved control rate [Hz] | {summary.achieved_hz:.2f} | | | {1 / period:.0f} |")
    print(f"| frames shown per second | {viewer.frames / seconds:.1f} | | | |")


if __name__ == "__main__":
    main()
