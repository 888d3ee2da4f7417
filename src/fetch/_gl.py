"""Pick an offscreen OpenGL backend for MuJoCo on a headless Linux machine, and say what is missing."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

from fetch.errors import FetchError

_OSMESA_NAMES = ("libOSMesa.so", *(f"libOSMesa.so.{i}" for i in range(9, -1, -1)))
"""The file names PyOpenGL tries, in its order (OpenGL/platform/ctypesloader.py)."""

_problem: str | None = None
"""Why MuJoCo cannot render in this process (set at `import fetch`), or None."""


def has_display() -> bool:
    """True when a window can be opened: always off Linux; on Linux when DISPLAY or WAYLAND_DISPLAY is set."""
    return sys.platform != "linux" or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def osmesa_loads() -> bool:
    """True when the OSMesa library loads the way PyOpenGL loads it (the dynamic loader, LD_LIBRARY_PATH)."""
    for name in _OSMESA_NAMES:
        try:
            ctypes.CDLL(name, mode=ctypes.RTLD_GLOBAL)
        except OSError:
            continue
        return True
    return False


def choose_gl_backend() -> str | None:
    """Set MUJOCO_GL to egl (else osmesa) when it is unset and there is no display.

    MuJoCo reads MUJOCO_GL once, when `mujoco` is first imported, so this must run before
    that; if mujoco is already imported, nothing is changed. Returns the value set, if any.

    With MUJOCO_GL=osmesa and no OSMesa library, `import mujoco` itself dies inside PyOpenGL
    (`'NoneType' object has no attribute 'glGetError'`), so nothing of the package could be used, not
    even what never renders. Then mujoco is imported here with its GL backend turned off for that
    import only, and rendering raises `check_gl()`'s error, which names the package to install.
    """
    global _problem
    if sys.platform != "linux" or "mujoco" in sys.modules:
        return None
    chosen = None
    if not os.environ.get("MUJOCO_GL") and not has_display():
        chosen = "egl" if ctypes.util.find_library("EGL") else "osmesa"
        os.environ["MUJOCO_GL"] = chosen
    requested = os.environ.get("MUJOCO_GL", "")
    if requested.strip().lower() == "osmesa" and not osmesa_loads():
        why = " (chosen by `import fetch`: no display and no EGL library)" if chosen else ""
        _problem = (f"MUJOCO_GL=osmesa{why} needs the OSMesa library (libOSMesa.so), which is not installed: "
                    "apt-get install libosmesa6, or use MUJOCO_GL=egl (libEGL, from libegl1)")
        os.environ["MUJOCO_GL"] = "disable"
        try:
            import mujoco  # noqa: F401  (with no GL backend, so that the import succeeds)
        finally:
            os.environ["MUJOCO_GL"] = requested
    return chosen


def check_gl() -> None:
    """Raise FetchError naming what to install when MuJoCo cannot render in this process."""
    if _problem is not None:
        raise FetchError(_problem)
