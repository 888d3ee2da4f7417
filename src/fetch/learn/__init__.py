"""Policies learnt from demonstrations: train, load, evaluate (needs torch: the `train` extra)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

from fetch.errors import FetchError, install_hint

if TYPE_CHECKING:
    from fetch.learn.runtime import Policy

TORCH_INSTALL = install_hint("train")
POLICY_KINDS = ("mlp-chunk", "gru")
"""`--policy` choices (the networks are in `policies.POLICIES`, which imports torch)."""
DEFAULT_POLICY = "gru"
MEASURED_POLICY: dict[str, str] = {"Drawer-close-v2": "mlp-chunk", "Push-v2": "mlp-chunk"}
"""Tasks whose best policy is not `DEFAULT_POLICY`, by measurement (docs/learning_curves.md, 100 DART
demos): on Drawer-close gru hovers over the handle and never pushes (0 % against mlp-chunk's 100 %),
whose action chunks carry the timing of the push; on Push the two tie (57 and 59 %) and mlp-chunk
trains ~7x faster."""


MEASURED_SETTINGS: dict[str, dict[str, Any]] = {
    "Push-v2": {"members": 5, "goal_offsets": True, "velocities": False, "chunk": 1}}
"""Settings `--policy auto` adds on tasks where they measured better: on Push an ensemble of 5 networks
that also sees the goal's offsets (`--goal-offsets`), does not see the velocities (`--no-velocities`)
and predicts one action at a time (`--chunk 1`). docs/learning_curves.md and docs/operators.md have the
measurements."""


MEASURED_MIRROR: frozenset[str] = frozenset({"Push-v2", "PickPlace-v2"})
"""Tasks on which `--policy auto` also learns from each demo's mirror image (`--mirror`), by
measurement (docs/learning_curves.md, 3 training seeds each): on Push the ensemble with goal offsets
went from 82.0 to 86.7 % (1000 evaluation episodes; with 10000 steps: twice the demos); on
PickPlace gru from 14.9 to 35.5 % with 10 demos and from 75.9 to 85.4 % with 30 (500 episodes)."""


DEFAULT_STEPS = 5000
"""Gradient steps `gym-fetch train` takes unless told (`--steps`, `--epochs`) or measured otherwise."""
MEASURED_STEPS: dict[str, int] = {"Bin-pick-v2": 10000, "Bin-place-v2": 10000, "Push-v2": 10000,
                                  "PickPlace-v2": 10000}
"""Tasks where more steps measured better (docs/learning_curves.md, 3 training seeds): on Bin-pick gru
83 % with 10000 steps against 80 % with 5000 (82.3 against 77.2 % over 500 evaluation episodes),
~3.5 CPU-minutes a run; on Push, learning from the demos and their mirror images, 86.7 against
84.5 % over 1000 (~2 minutes a run); on PickPlace, on the mission's 1000 demos generated from 10 pad
demos, 96.5 against 89.9 % over 500 (docs/benchmarks.md, "The whole path"; ~3.5 CPU-minutes), and
with 10 or 30 expert demos the same or better (27.8 against 29.0 %, 85.6 against 81.6 %; one seed);
on Bin-place, on the mission's 1000 generated demos, 93 / 93 / 93 % against 87 % (one seed) on the
benchmark's 100 episodes and 95.2 against 94.4 % over 500 (~4 CPU-minutes); on its 100 expert demos
86 +- 3 against 85 +- 7 %."""


def default_steps(env_id: str) -> int:
    """The gradient steps `gym-fetch train` takes on a dataset of `env_id` unless told otherwise."""
    return MEASURED_STEPS.get(env_id, DEFAULT_STEPS)


def policy_for(env_id: str) -> str:
    """The kind of policy `gym-fetch train --policy auto` trains on a dataset of `env_id`."""
    return MEASURED_POLICY.get(env_id, DEFAULT_POLICY)


def auto_settings(env_id: str) -> dict[str, Any]:
    """The policy settings (`kind` and any measured exceptions) `--policy auto` trains on `env_id`."""
    return {"kind": policy_for(env_id), **MEASURED_SETTINGS.get(env_id, {})}


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


__all__ = ["DEFAULT_POLICY", "DEFAULT_STEPS", "MEASURED_MIRROR", "MEASURED_POLICY", "MEASURED_SETTINGS",
           "MEASURED_STEPS", "POLICY_KINDS", "TORCH_INSTALL", "auto_settings", "default_steps", "load", "policy_for",
           "require_torch"]
