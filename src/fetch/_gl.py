"""Offscreen OpenGL for MuJoCo, chosen when the first renderer is made, not at import.

`import fetch` changes nothing in the process environment. A renderer reads `MUJOCO_GL` when it
is made, as MuJoCo does: egl, osmesa or glfw when set; unset, the display's GL when there is a
display, and on a headless Linux machine EGL, else OSMesa. (MuJoCo's own `mujoco.egl` sets
`PYOPENGL_PLATFORM` when the EGL backend is first imported; that happens then, not at import.)
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
from typing import Any

from fetch._environ import environ
from fetch.errors import FetchError

_OSMESA_NAMES = ("libOSMesa.so", *(f"libOSMesa.so.{i}" for i in range(9, -1, -1)))
"""The file names PyOpenGL tries, in its order (OpenGL/platform/ctypesloader.py)."""

_problem: str | None = None
"""Why MuJoCo cannot render in this process (found at `import fetch`), or None."""

_OSMESA_MISSING = ("MUJOCO_GL=osmesa{why} needs the OSMesa library (libOSMesa.so), which is not installed: "
                   "apt-get install libosmesa6, or use MUJOCO_GL=egl (libEGL, from libegl1)")


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


def guard_mujoco_import() -> None:
    """Import mujoco without the GL backend it would load itself, where that backend is of no use or harm:

    - MUJOCO_GL=osmesa and no OSMesa library: `import mujoco` itself dies inside PyOpenGL (`'NoneType'
      object has no attribute 'glGetError'`), so nothing of the package could be used, not even what
      never renders; rendering then raises `check_gl()`'s error, which names the package to install.
    - MUJOCO_GL unset on a Linux machine without a display: mujoco loads GLFW, which cannot open a
      context there, and whose library search starts a Python subprocess for each GLFW library it finds
      (pyGLFW's version check), in every process that imports mujoco, workers included. A terminal's
      Ctrl-C goes to the whole process group and ended that subprocess with a traceback on screen
      (`EOFError` or `BrokenPipeError` in `<string>`). `mujoco.GLContext` is then the context fetch's
      renderers use (`context_class`, EGL or OSMesa), made when first used, so `mujoco.Renderer` works.

    The variable is put back right after the import."""
    global _problem
    if sys.platform != "linux" or "mujoco" in sys.modules:
        return
    requested = os.environ.get("MUJOCO_GL", "").strip().lower()
    if requested == "osmesa" and not osmesa_loads():
        _problem = _OSMESA_MISSING.format(why="")
        _import_mujoco_without_gl()
    elif not requested and not has_display():
        _import_mujoco_without_gl()
        import mujoco

        for module in (mujoco, sys.modules[mujoco.Renderer.__module__].gl_context):  # type: ignore[attr-defined]
            module.GLContext = _ChosenContext


def _import_mujoco_without_gl() -> None:
    with environ(overwrite=True, MUJOCO_GL="disable"):
        import mujoco  # noqa: F401  (with no GL backend)


class _ChosenContext:
    """`mujoco.GLContext` where `guard_mujoco_import` left MuJoCo's own out: a context of the backend
    `context_class` picks when one is made."""

    def __new__(cls, *args: Any, **kwargs: Any) -> Any:
        return context_class()(*args, **kwargs)


def check_gl() -> None:
    """Raise FetchError naming what to install when MuJoCo cannot render in this process."""
    if _problem is not None:
        raise FetchError(_problem)


def backend() -> str:
    """The offscreen backend a renderer made now uses: egl, osmesa, or mujoco (MuJoCo's own choice)."""
    requested = os.environ.get("MUJOCO_GL", "").strip().lower()
    if sys.platform != "linux" or requested not in ("", "egl", "osmesa"):
        return "mujoco"
    if requested:
        return requested
    if has_display():
        return "mujoco"
    return "egl" if ctypes.util.find_library("EGL") else "osmesa"


def context_class() -> Any:
    """The GL context class for a renderer made now (see the module docstring)."""
    check_gl()
    chosen = backend()
    if chosen == "osmesa" and not osmesa_loads():
        why = "" if os.environ.get("MUJOCO_GL") else " (no display and no EGL library)"
        raise FetchError(_OSMESA_MISSING.format(why=why))
    try:
        if chosen == "egl":
            from mujoco.egl import GLContext
        elif chosen == "osmesa":
            from mujoco.osmesa import GLContext  # type: ignore[no-redef]
        else:
            import mujoco

            own = getattr(sys.modules[mujoco.Renderer.__module__].gl_context, "GLContext", None)  # type: ignore[attr-defined]
            # Imported without its backend (`guard_mujoco_import`): GLFW, MuJoCo's own choice on Linux.
            if own is None or own is _ChosenContext:
                from mujoco.glfw import GLContext  # type: ignore[no-redef]
            else:
                GLContext = own
    except Exception as e:  # the GL backends' own error types vary
        raise FetchError(f"cannot load MuJoCo's {chosen} OpenGL backend: {e}. Set MUJOCO_GL=egl (libEGL, from "
                         "libegl1) or osmesa (apt-get install libosmesa6)") from e
    return GLContext


def make_renderer(model: Any, height: int, width: int) -> Any:
    """A `mujoco.Renderer` on `context_class()`'s context. MuJoCo's Renderer makes its context from
    its module's `gl_context.GLContext`, fixed when mujoco was imported; that one name is pointed at
    the chosen class while the Renderer is made, and put back."""
    import mujoco

    cls = context_class()
    module = sys.modules[mujoco.Renderer.__module__].gl_context  # type: ignore[attr-defined]
    saved = getattr(module, "GLContext", None)  # none where mujoco was imported without a backend
    module.GLContext = cls
    try:
        return mujoco.Renderer(model, height=height, width=width)
    finally:
        if saved is None:
            del module.GLContext
        else:
            module.GLContext = saved
