"""Policies learnt from demonstrations: train, load, evaluate (needs torch: the `train` extra)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from fetch.errors import FetchError

if TYPE_CHECKING:
    from fetch.learn.runtime import Policy

TORCH_INSTALL = 'pip install "gym-fetch-v2[train]"'
POLICY_KINDS = ("mlp-chunk", "gru")
"""`--policy` choices (the networks are in `policies.POLICIES`, which imports torch)."""


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


__all__ = ["POLICY_KINDS", "TORCH_INSTALL", "load", "require_torch"]
