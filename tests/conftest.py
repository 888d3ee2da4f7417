"""Shared fixtures: every registered env id, envs closed after each test, a small real dataset."""

from __future__ import annotations

import os
import pathlib
import sys
from collections.abc import Iterator
from typing import Any


def _working_folder_off_the_path() -> None:
    """`python -m pytest` puts the working folder first on sys.path, so a folder left there named like a
    package (`lerobot/`, from an export) would be imported in its place (issue 72). The tests import installed
    packages and their own helpers only (this folder, which pytest puts on the path itself)."""
    here = pathlib.Path(__file__).resolve().parent
    working = pathlib.Path.cwd().resolve()
    if working != here:
        sys.path[:] = [p for p in sys.path if pathlib.Path(os.path.abspath(p or ".")).resolve() != working]


_working_folder_off_the_path()

import gymnasium as gym  # noqa: E402  (after the working folder is off the path)
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import fetch  # noqa: E402

ENV_IDS = list(fetch.ENV_IDS)


@pytest.fixture(params=ENV_IDS)
def env_id(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def pad(monkeypatch: pytest.MonkeyPatch) -> Iterator[object]:
    """An Xbox-layout virtual pad (fetch.testing.vpad); SDL is process-global, so pygame is shut down after."""
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


def expert_demos(tmp_path_factory: pytest.TempPathFactory, env_id: str, episodes: int) -> pathlib.Path:
    """A new collector's directory with `episodes` expert demos of `env_id` (`gym-fetch collect`)."""
    from fetch.cli import main

    out = tmp_path_factory.mktemp(env_id) / "demos"
    assert main(["collect", "--env", env_id, "--device", "expert", "--episodes", str(episodes), "--render", "none",
                 "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def torch():  # noqa: ANN201
    """torch, for the tests that train or load a policy; they skip where it is not installed (the base venv)."""
    return pytest.importorskip("torch")


def objects_state(layout: dict[str, slice]) -> np.ndarray:
    """A mask over the state observation an env's `observation_layout` describes: True at every entry but the
    robot's own readings (`fetch.learn.data.PROPRIOCEPTION`), what a camera policy must not see. Made from the
    layout, not from the policy's own list of what it is blind to, so a check of that list is not circular."""
    from fetch.learn.data import PROPRIOCEPTION

    hidden = np.ones(max(part.stop for part in layout.values()), bool)
    for name in PROPRIOCEPTION:
        hidden[layout[name]] = False
    return hidden


def hide_objects(obs: dict[str, np.ndarray], hidden: np.ndarray) -> dict[str, np.ndarray]:
    """A copy of `obs` (one env's or a batch's) with the objects' state (`objects_state`) and the achieved goal,
    the object's position, NaN."""
    shown = {k: np.array(v, copy=True) for k, v in obs.items()}
    shown["observation"][..., hidden] = np.nan
    shown["achieved_goal"][...] = np.nan
    return shown


@pytest.fixture(scope="session")
def reach_demos(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """A collector's directory with two Reach-v2 expert demos, made once per run; copy it to change it."""
    return expert_demos(tmp_path_factory, "Reach-v2", 2)


SLOW = frozenset((pathlib.Path(__file__).parent / "slow.txt").read_text().splitlines())
"""Node ids of the tests the `slow` marker selects (`scripts/mark_slow.py` writes them from a timed run)."""


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: over 0.5 s in the last timed run (tests/slow.txt); "
                                       "pytest -m 'not slow' runs the rest in under 2 minutes on 2 cores")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.nodeid in SLOW:
            item.add_marker(pytest.mark.slow)


class StretchCorrector:
    """A person who takes over on every other stretch of 6 ticks and steers to the goal (no pad: the
    takeover device reads its commands as it would a pad's)."""

    name = "gamepad"

    def __init__(self) -> None:
        self.tick = 0

    def reset(self) -> None:
        self.tick = 0

    def poll(self, obs: dict) -> Any:
        from fetch.teleop.devices import Command

        self.tick += 1
        if (self.tick // 6) % 2 == 0:
            return Command(np.zeros(4, np.float32))
        move = np.clip((obs["desired_goal"] - obs["achieved_goal"]) / 0.05, -1, 1)
        return Command(np.r_[move, 1.0].astype(np.float32), touched=True)

    def close(self) -> None:
        pass
