"""The package's exceptions: one base class, a few specific ones."""

from __future__ import annotations


class FetchError(Exception):
    """Base class of every error this package raises on purpose."""


class UnknownNameError(FetchError, KeyError):
    """A name (task, camera, render mode, ...) that is not one of the valid choices."""

    def __init__(self, kind: str, name: object, choices: list[str] | tuple[str, ...]) -> None:
        self.kind, self.name, self.choices = kind, name, tuple(choices)
        super().__init__(f"unknown {kind} {name!r}; known: {', '.join(self.choices)}")

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


class DatasetError(FetchError):
    """A dataset that cannot be read or written as asked: missing, foreign, corrupt, locked, mismatched."""


class OutsideError(DatasetError):
    """A folder's file names a path outside the folder (absolute, `..`, a symbolic link out), or a tool
    would write through a link: refused before anything is read, written or moved (docs/security.md)."""


def install_hint(extra: str) -> str:
    """The command that adds an optional part (a `pyproject.toml` extra): gym-fetch-v2 installs from its
    source tree, so it is `pip install ".[extra]"` run there (`pip install "gym-fetch-v2[extra]"` would
    look for it on PyPI, where it is not)."""
    return f'pip install ".[{extra}]" (in the gym-fetch-v2 source tree)'


def one_line(e: BaseException | str) -> str:
    """An error's message on one line (HDF5's and torch's span several)."""
    return " ".join(str(e).split()) or type(e).__name__
