"""Policies learnt from demonstrations: train, load, evaluate (needs torch: the `train` extra).

`kinds.py` declares the kinds of policy and `policies.py` their torch side; `settings.py` decides what
a run trains unless told (the CLI and `train.train` alike); `data.py` reads demos; `train.py`,
`runtime.py` (a trained policy as a callable) and `evaluate.py` run them; `checkpoint.py` reads and writes a
run's file, every field of which `checked.py` checks before use; `device.py` and `takeover.py` make a policy a
collection device.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from fetch.errors import FetchError, install_hint

if TYPE_CHECKING:
    from fetch.learn.runtime import Policy

TORCH_INSTALL = install_hint("train")


def require_torch() -> None:
    """FetchError with the install command when torch cannot be imported."""
    try:
        import torch  # noqa: F401
    except ImportError as e:
        raise FetchError(f"training and running policies needs PyTorch, which cannot be imported ({e}); "
                         f"install it with: {TORCH_INSTALL}") from e


def load(run: str | os.PathLike[str]) -> Policy:
    """The policy of a `gym-fetch train` run directory: `policy.reset()`, then `action = policy(obs)`."""
    require_torch()
    from fetch.learn.runtime import load as load_run

    return load_run(run)


__all__ = ["TORCH_INSTALL", "load", "require_torch"]
