"""Each task's training recipe: what `gym-fetch train --policy auto` trains on it unless told otherwise."""

from __future__ import annotations

from typing import NamedTuple

from fetch.errors import UnknownNameError
from fetch.tasks import ENV_IDS


class Training(NamedTuple):
    """How `gym-fetch train` (`--policy auto`) learns a task unless told otherwise: the choices measured
    best on it (docs/training.md, "Each task's defaults", has the measurements)."""

    policy: str = "gru"
    """the kind of policy (`fetch.learn.kinds.KINDS`)."""
    steps: int = 5000
    """gradient steps."""
    mirror: bool = False
    """also learn from each demo's mirror image (`Task.mirrors` tasks only)."""
    members: int = 1
    """networks in the ensemble."""
    goal_offsets: bool = False
    """also see the goal relative to the achieved goal and to the grip site."""
    velocities: bool = True
    """see the observation's velocities (a pixel policy: the robot's own)."""
    chunk: int | None = None
    """mlp-chunk: actions per prediction (None: the kind's default)."""


RECIPES: dict[str, Training] = {
    "Bin-pick-v2": Training(steps=10000),
    "Bin-place-v2": Training(steps=10000),
    "Drawer-close-v2": Training(policy="mlp-chunk"),
    "Push-v2": Training(policy="mlp-chunk", steps=10000, mirror=True, members=5, goal_offsets=True,
                        velocities=False, chunk=1),
    "PickPlace-v2": Training(steps=10000, mirror=True, velocities=False),
}
"""The registered ids (`fetch.tasks.ENV_IDS`) whose recipe measurement set apart from `Training()`; every
other id trains with `Training()`."""

_STRAYS = sorted(set(RECIPES) - set(ENV_IDS))
if _STRAYS:  # a renamed task would otherwise lose its recipe without a word
    raise UnknownNameError("env", _STRAYS[0], ENV_IDS)


def task_training(env_id: str) -> Training:
    """What `--policy auto` trains on `env_id` unless told otherwise (its line in `RECIPES`, else `Training()`)."""
    if env_id not in ENV_IDS:
        raise UnknownNameError("env", env_id, ENV_IDS)
    return RECIPES.get(env_id, Training())
