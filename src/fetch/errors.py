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
