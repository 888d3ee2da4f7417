"""The task table: each registered Gymnasium id, its task and its horizon, one line each. Everything else
about a task is on its class (`tasks.base.Task`): its scene, observation, success rule, subtasks,
instruction, expert and the window's view; how a policy learns it is in `fetch.learn.recipes`."""

from __future__ import annotations

from typing import NamedTuple

from fetch.errors import UnknownNameError
from fetch.tasks.base import Task
from fetch.tasks.bin import BinPick, BinPlace
from fetch.tasks.box import BoxClose, BoxOpen
from fetch.tasks.classic import PickPlace, Push, Reach, Slide
from fetch.tasks.drawer import DrawerClose, DrawerOpen


class Registration(NamedTuple):
    env_id: str
    task: type[Task]
    max_episode_steps: int


REGISTRATIONS: tuple[Registration, ...] = (
    Registration("Bin-pick-v2", BinPick, 50),
    Registration("Bin-place-v2", BinPlace, 50),
    Registration("Box-open-v2", BoxOpen, 50),
    Registration("Box-close-v2", BoxClose, 50),
    Registration("Drawer-open-v2", DrawerOpen, 50),
    Registration("Drawer-close-v2", DrawerClose, 50),
    Registration("Reach-v2", Reach, 50),
    Registration("Push-v2", Push, 50),
    Registration("PickPlace-v2", PickPlace, 50),
    Registration("Slide-v2", Slide, 50),
)

ENV_IDS: tuple[str, ...] = tuple(r.env_id for r in REGISTRATIONS)
_BY_NAME: dict[str, type[Task]] = {r.task.name: r.task for r in REGISTRATIONS}
_BY_ID: dict[str, type[Task]] = {r.env_id: r.task for r in REGISTRATIONS}


_BY_ENV_ID: dict[str, Registration] = {r.env_id: r for r in REGISTRATIONS}


MAX_STEPS = 100_000
"""[steps] the longest attempt a tool runs (`--max-steps`): over an hour at the control rate of 25 Hz; an
attempt that never ends (a typo of a few zeros) is refused."""


def registered_horizon(env_id: str) -> int:
    """[steps] the episode length `env_id` is registered with (Fetch's 50)."""
    return registration(env_id).max_episode_steps


def registration(env_id: str) -> Registration:
    """The task table's line for `env_id`."""
    if env_id not in _BY_ENV_ID:
        raise UnknownNameError("env", env_id, ENV_IDS)
    return _BY_ENV_ID[env_id]


def mirroring_ids() -> tuple[str, ...]:
    """The ids whose task is symmetric about the plane through its start (`Task.mirrors`)."""
    return tuple(r.env_id for r in REGISTRATIONS if r.task.mirrors)


def task_names() -> tuple[str, ...]:
    return tuple(_BY_NAME)


def task_class(name: str) -> type[Task]:
    """The task for a task name ("bin_pick") or a registered id ("Bin-pick-v2")."""
    found = _BY_NAME.get(name) or _BY_ID.get(name)
    if found is None:
        raise UnknownNameError("task", name, ENV_IDS + task_names())
    return found
