"""Pick an offscreen OpenGL backend for MuJoCo on a headless Linux machine."""

from __future__ import annotations

import ctypes.util
import os
import sys


def choose_gl_backend() -> str | None:
    """Set MUJOCO_GL to egl (else osmesa) when it is unset and there is no display.

    MuJoCo reads MUJOCO_GL once, when `mujoco` is first imported, so this must run before
    that; if mujoco is already imported, nothing is changed. Returns the value set, if any.
    """
    if os.environ.get("MUJOCO_GL") or sys.platform != "linux" or "mujoco" in sys.modules:
        return None
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    backend = "egl" if ctypes.util.find_library("EGL") else "osmesa"
    os.environ["MUJOCO_GL"] = backend
    return backend
