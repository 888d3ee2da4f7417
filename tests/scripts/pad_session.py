"""A headless gamepad collection with a virtual pad plugged in (SDL's video subsystem running, as
with a real pad), for the signal tests: `python pad_session.py OUT`."""

from __future__ import annotations

import os
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))
os.environ["SDL_VIDEODRIVER"] = "dummy"

import vpad  # noqa: E402
from fetch.cli import main  # noqa: E402

vpad.init_headless()  # SDL starts here, before the collector, and installs its own SIGTERM handler
pad = vpad.VirtualPad()
print("pad ready", flush=True)
sys.exit(main(["collect", "--env", "Reach-v2", "--device", "gamepad", "--render", "none", "--out", sys.argv[1]]))
