"""Process probes, for the tests that `import procs`: they live in `fetch.testing.procs`."""

from fetch.testing.procs import alive, children, command_line

__all__ = ["alive", "children", "command_line"]
