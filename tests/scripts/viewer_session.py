"""Run by tests/test_viewer.py under Xvfb: a real collection session with the viewer window.

Usage: viewer_session.py OUT SCREENSHOT -- the expert collects 2 PickPlace-v2 demos at 25 Hz;
a screenshot of the window is saved at the 5th frame; the timing is printed as JSON.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from fetch.teleop.expert import ExpertDevice
from fetch.teleop.gamepad import KIND as GAMEPAD
from fetch.teleop.session import CollectConfig, HudState, Session, make_env
from fetch.teleop.viewer import Viewer


class ShootingViewer(Viewer):
    def __init__(self, *args: object, path: str, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.path = path

    def show(self, hud: HudState) -> None:
        before = self.frames
        super().show(hud)
        if self.frames == 5 and before == 4:
            self.screenshot(self.path)


def main() -> None:
    out, shot = sys.argv[1], sys.argv[2]
    config = CollectConfig(env_id="PickPlace-v2", out=out, episodes=2, device="expert", render="human")
    env = make_env(config)
    viewer = ShootingViewer(env, GAMEPAD.legend, path=shot)
    session = Session(config, ExpertDevice(env), env=env, display=viewer)
    import pygame

    driver = pygame.display.get_driver()  # while the window is open: x11 under Xvfb, not a dummy
    summary = session.run()
    ticks = np.array(session.ticks)
    late = (ticks[:, 1] - ticks[:, 0]) * 1000.0
    print(json.dumps({"saved": summary.saved, "achieved_hz": summary.achieved_hz, "frames": viewer.frames,
                      "ticks": viewer.ticks, "p99_late_ms": float(np.percentile(late, 99)), "driver": driver}))


if __name__ == "__main__":
    main()
