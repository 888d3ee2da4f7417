"""Shared fixtures: every registered env id, envs closed after each test, a small real dataset."""

from __future__ import annotations

import pathlib
from collections.abc import Iterator

import gymnasium as gym
import pytest

import fetch

ENV_IDS = list(fetch.ENV_IDS)


@pytest.fixture(params=ENV_IDS)
def env_id(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def pad(monkeypatch: pytest.MonkeyPatch) -> Iterator[object]:
    """An Xbox-layout virtual pad (tests/vpad.py); SDL is process-global, so pygame is shut down after."""
    import pygame

    import vpad

    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    vpad.init_headless()
    virtual = vpad.VirtualPad()
    yield virtual
    virtual.close()
    pygame.quit()


@pytest.fixture
def env(env_id: str) -> Iterator[gym.Env]:
    made = gym.make(env_id)
    yield made
    made.close()


def rollout_actions(env: gym.Env, n: int, seed: int = 0):
    """`n` reproducible random actions in the env's action space."""
    space = env.action_space
    space.seed(seed)
    return [space.sample() for _ in range(n)]


@pytest.fixture(scope="session")
def reach_demos(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """A collector's directory with two Reach-v2 expert demos, made once per run; copy it to change it."""
    from fetch.cli import main

    out = tmp_path_factory.mktemp("reach") / "demos"
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "2", "--render", "none",
                 "--out", str(out)]) == 0
    return out


SLOW = frozenset((pathlib.Path(__file__).parent / "slow.txt").read_text().splitlines())
"""Node ids of the tests the `slow` marker selects (`scripts/mark_slow.py` writes them from a timed run)."""


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: over 0.5 s in the last timed run (tests/slow.txt); "
                                       "pytest -m 'not slow' runs the rest in under 2 minutes on 2 cores")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.nodeid in SLOW:
            item.add_marker(pytest.mark.slow)
