"""A reference to a Python object by name, "package.module:attribute", resolved when first needed.

Gymnasium's `entry_point` does the same. A record in a low layer (a task's expert, a policy kind's
network) names the code that a higher layer, or a heavy dependency such as torch, provides, without
importing it: the task table stays importable without the experts, the CLI without torch.
"""

from __future__ import annotations

import importlib
from typing import Any

from fetch.errors import FetchError


def resolve(reference: str) -> Any:
    """The object `reference` ("package.module:attribute") names; FetchError if there is none."""
    module, sep, attribute = reference.partition(":")
    if not sep or not module or not attribute:
        raise FetchError(f"a reference is 'package.module:attribute', got {reference!r}")
    try:
        found = importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name is None or not module.startswith(e.name):
            raise  # the module exists but something it imports does not: that error is the one to see
        raise FetchError(f"{reference!r}: no module {module}") from e
    for name in attribute.split("."):
        if not hasattr(found, name):
            raise FetchError(f"{reference!r}: {found.__name__ if hasattr(found, '__name__') else module} "
                             f"has no {name}")
        found = getattr(found, name)
    return found
