"""The virtual SDL pad, for the tests that `import vpad`: it lives in `fetch.testing.vpad`."""

from fetch.testing.vpad import AXES, BUTTONS, VirtualPad, init_headless, sdl_library

__all__ = ["AXES", "BUTTONS", "VirtualPad", "init_headless", "sdl_library"]
