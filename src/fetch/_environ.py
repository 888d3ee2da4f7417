"""Process-environment variables set for the length of one call (SDL reads its hints when a subsystem starts)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator


@contextlib.contextmanager
def environ(overwrite: bool = False, **values: str) -> Iterator[None]:
    """Set `values` in `os.environ` inside the block and put back what was there after it. Without
    `overwrite`, a variable the user already set is left as it is (their choice wins)."""
    saved = {name: os.environ.get(name) for name in values}
    for name, value in values.items():
        if overwrite or name not in os.environ:
            os.environ[name] = value
    try:
        yield
    finally:
        for name, old in saved.items():
            if old is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = old
