"""Scripted experts, one per task: `expert = make_expert(env)`, `expert.reset()`, `action = expert(obs)`.

Each task names its expert (`Task.expert`): a class of `motion.py`, or one of the recipes here, which
set the generic pick-and-place expert's grasp for a task's object."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import cast

import gymnasium as gym

from fetch._references import resolve
from fetch.env import FetchEnv
from fetch.errors import FetchError
from fetch.experts.base import Expert
from fetch.experts.pick import Grasp, PickAndPlace
from fetch.experts.slide import Slide
from fetch.experts.twin import Twin
from fetch.tasks import bin as bin_task
from fetch.tasks import box as box_task
from fetch.tasks import classic
from fetch.tasks.base import Task

__all__ = ["Expert", "expert_factory", "make_expert"]

# Handle: the grip site 2.2 cm above the lid's top face, so the fingertips clear the lid.
_HANDLE = (0.0, 0.0, box_task.LID_THICK / 2 + 0.022)
_BIN_CARRY = bin_task.TABLE_TOP + bin_task.WALL_HEIGHT + 2 * bin_task.BLOCK + 0.03
_BOX_CARRY = box_task.SEATED_Z + _HANDLE[2] + 0.04

def pick_place(layout: Mapping[str, slice]) -> Expert:
    return PickAndPlace(layout, Grasp("object"))


def bin_pick(layout: Mapping[str, slice]) -> Expert:
    return PickAndPlace(layout, Grasp("block", opening=0.03, carry_z=_BIN_CARRY))


def bin_place(layout: Mapping[str, slice]) -> Expert:
    return PickAndPlace(layout, Grasp("block", opening=0.03, carry_z=_BIN_CARRY, release=True))


def box_open(layout: Mapping[str, slice]) -> Expert:
    return PickAndPlace(layout, Grasp("lid", _HANDLE, opening=0.02, carry_z=_BOX_CARRY, release=True))


def box_close(layout: Mapping[str, slice]) -> Expert:
    return PickAndPlace(layout, Grasp("lid", _HANDLE, opening=0.02, carry_z=_BOX_CARRY, release=True,
                                      release_tolerance=0.006))


def slide(layout: Mapping[str, slice]) -> Expert:
    """Slide plans in a private copy of its own task (`experts.twin`), started from the first observation."""
    return Slide(layout, twin=Twin(FetchEnv(task=classic.Slide.name)))


def expert_factory(task: type[Task]) -> Callable[[Mapping[str, slice]], Expert]:
    """The callable `task.expert` names: observation layout -> the task's expert."""
    return cast(Callable[[Mapping[str, slice]], Expert], resolve(task.expert))


def make_expert(env: gym.Env | str) -> Expert:
    """The scripted expert for an env (or a registered id such as "Drawer-open-v2")."""
    if isinstance(env, str):
        env = gym.make(env)
    unwrapped = env.unwrapped
    if not isinstance(unwrapped, FetchEnv):
        raise FetchError(f"make_expert needs a gym-fetch env or id, got {type(unwrapped).__name__}")
    return expert_factory(type(unwrapped.task))(unwrapped.observation_layout)
