"""Each task's training recipe (`fetch.learn.recipes`): keyed by registered ids, looked up by id only."""

from __future__ import annotations

import pytest

from fetch.errors import UnknownNameError
from fetch.learn.recipes import RECIPES, Training, task_training
from fetch.tasks import ENV_IDS


def test_every_recipe_is_for_a_registered_id_and_every_id_has_one() -> None:
    assert set(RECIPES) <= set(ENV_IDS)
    assert task_training("Reach-v2") == Training() and task_training("Push-v2") is RECIPES["Push-v2"]


def test_an_unknown_id_is_refused_with_the_known_ones() -> None:
    with pytest.raises(UnknownNameError, match="unknown env 'Bin-pik-v2'; known: Bin-pick-v2"):
        task_training("Bin-pik-v2")
