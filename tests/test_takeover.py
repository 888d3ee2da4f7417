"""A person corrects a policy through the real pad path (SDL virtual pad, issue 41): any stick input takes
the arm over, letting go hands it back, nothing jumps at a switch, and every step records who drove and
what the policy proposed, on disk and in every export."""

from __future__ import annotations

import json
import pathlib
from collections.abc import Mapping

import minari
import numpy as np
import pytest

import vpad  # fetch.testing.vpad, re-exported by tests/vpad.py
from fetch.dataset import open_dataset, validate
from fetch.dataset.exports.export import export_minari, export_npz
from fetch.dataset.reader import summarize, takeovers
from fetch.dataset.replay.check import check_demo
from fetch.learn.takeover import HAND_BACK, TakeoverDevice
from fetch.teleop.devices import Command
from fetch.teleop.gamepad import GamepadConfig, GamepadDevice
from fetch.teleop.session import CollectConfig, Session

DRIFT = np.array([0.6, 0.0, 0.0, 1.0], np.float32)
"""The policy's one action: the hand drifts along +x, away from where it should go."""
FIRST, HELD, SECOND = 5, 10, 34
"""The person takes over at tick FIRST + 1, steers for HELD ticks, lets go, and takes over again at
tick SECOND + 1 to finish the attempt."""


class DriftingPolicy:
    """A policy that pushes the hand one way, whatever it sees (the real policy device's interface)."""

    name = "policy"

    def __init__(self) -> None:
        self.polls = 0

    def reset(self) -> None:
        pass

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        self.polls += 1
        return Command(DRIFT.copy())

    def close(self) -> None:
        pass


class Person:
    """Moves the virtual pad's stick at the scripted ticks, then lets the real gamepad device read it."""

    name = "gamepad"

    def __init__(self, pad: vpad.VirtualPad) -> None:
        self.pad, self.device = pad, GamepadDevice(GamepadConfig(deadzone=0.05))
        self.tick = 0

    def reset(self) -> None:
        self.device.reset()
        self.tick = 0

    def gripper_from(self, action: np.ndarray | None) -> None:
        self.device.gripper_from(action)

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        self.tick += 1
        if FIRST < self.tick <= FIRST + HELD:  # the first correction lifts the hand
            self.pad.set_stick(0.0, 0.0)
            self.pad.set_triggers(0.0, 0.5)
        elif self.tick > SECOND:  # the second steers to the goal: x right, y up (SDL's y axis points down)
            x, y, z = np.clip((obs["desired_goal"] - obs["achieved_goal"]) / 0.05, -1, 1)
            self.pad.set_stick(float(x), float(-y))
            self.pad.set_triggers(max(0.0, -float(z)), max(0.0, float(z)))
        else:
            self.pad.set_stick(0.0, 0.0)
            self.pad.set_triggers(0.0, 0.0)
        return self.device.poll(obs)

    def close(self) -> None:
        self.device.close()


@pytest.fixture
def corrected(pad: vpad.VirtualPad, tmp_path: pathlib.Path) -> tuple[pathlib.Path, TakeoverDevice, list[Command]]:
    policy = DriftingPolicy()
    device = TakeoverDevice(policy, Person(pad))
    commands: list[Command] = []
    poll = device.poll

    def polled(obs: Mapping[str, np.ndarray]) -> Command:
        commands.append(poll(obs))
        return commands[-1]

    device.poll = polled  # type: ignore[method-assign]
    config = CollectConfig(env_id="Reach-v2", out=str(tmp_path / "demos"), device="takeover", render="none",
                           control_hz=0, success_hold_steps=8, max_steps=200, episodes=1)
    summary = Session(config, device, log=lambda text: None).run()
    assert summary.attempts[0].ended_by == "success", summary.describe()
    assert policy.polls == len(commands), "the policy is asked every tick, driving or not"
    return tmp_path / "demos", device, commands


def test_the_person_takes_over_at_once_and_hands_back_after_letting_go(
        corrected: tuple[pathlib.Path, TakeoverDevice, list[Command]]) -> None:
    out, device, commands = corrected
    person = [c.intervention for c in commands]
    # The policy drives until the stick moves; the person from that tick, through the stick's release, until
    # HAND_BACK ticks without input; then the policy until the second takeover, which finishes the attempt.
    back = FIRST + HELD + HAND_BACK
    assert person[:FIRST] == [False] * FIRST
    assert person[FIRST:back - 1] == [True] * (HELD + HAND_BACK - 1)
    assert person[back - 1:SECOND] == [False] * (SECOND - back + 1)
    assert all(person[SECOND:])
    assert device.takeovers == 2 and "takeovers 2" in commands[-1].status and "YOU drive" in commands[-1].status
    assert "the policy drives" in commands[FIRST - 1].status
    with open_dataset(out) as ds:
        assert validate(ds) == []
        demo = ds.arrays("demo_0")
        flags = demo["intervention"]
        assert flags.dtype == np.uint8 and flags.tolist() == [int(p) for p in person]
        assert takeovers(flags) == 2 and summarize(ds).corrections == (1, 2, int(flags.sum()), len(flags))
        np.testing.assert_array_equal(demo["policy_actions"], np.tile(DRIFT, (len(flags), 1)))
        driven = flags == 0
        np.testing.assert_array_equal(demo["actions"][driven], demo["policy_actions"][driven])
        assert not np.allclose(demo["actions"][~driven], DRIFT), "the person's actions are recorded as applied"
        # No jump at a switch: the hand moves at most one action's worth (5 cm per axis) in any step, and
        # across each switch no more than in the steps beside it.
        grip = np.concatenate([demo["obs/observation"][:, :3], demo["next_obs/observation"][-1:, :3]])
        moves = np.linalg.norm(np.diff(grip, axis=0), axis=1)
        assert moves.max() <= 0.05 * np.sqrt(3) + 1e-3
        for switch in np.flatnonzero(np.diff(flags.astype(int))) + 1:
            assert moves[switch] <= moves[switch - 3: switch + 3].max() + 1e-9
        check = check_demo(ds, "demo_0")
        assert check.exact, check.largest


def test_the_labels_go_into_every_export(corrected: tuple[pathlib.Path, TakeoverDevice, list[Command]],
                                         tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out, _, _ = corrected
    with open_dataset(out) as ds:
        arrays = ds.arrays("demo_0")
    export_npz(out, tmp_path / "npz")
    (npz,) = sorted((tmp_path / "npz").glob("*.npz"))
    with np.load(npz) as packed:
        np.testing.assert_array_equal(packed["intervention"], arrays["intervention"])
        np.testing.assert_array_equal(packed["policy_action"], arrays["policy_actions"])
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    export_minari(out, "fetch/reach/corrected-v0")
    episode = next(iter(minari.load_dataset("fetch/reach/corrected-v0").iterate_episodes()))
    np.testing.assert_array_equal(episode.infos["intervention"][1:], arrays["intervention"])
    np.testing.assert_array_equal(episode.infos["policy_action"][1:], arrays["policy_actions"])
    pq = pytest.importorskip("pyarrow.parquet")
    pytest.importorskip("av")
    from fetch.dataset.exports.export import export_lerobot

    export_lerobot(out, "local/corrected", tmp_path / "lerobot")
    table = pq.read_table(tmp_path / "lerobot" / "data" / "chunk-000" / "file-000.parquet")
    assert table.column("intervention").to_pylist() == arrays["intervention"].astype(bool).tolist()
    np.testing.assert_allclose(np.array(table.column("policy_action").to_pylist()), arrays["policy_actions"])
    info = json.loads((tmp_path / "lerobot" / "meta" / "info.json").read_text())
    assert info["features"]["intervention"]["dtype"] == "bool"


def test_the_view_marks_where_the_person_drove(corrected: tuple[pathlib.Path, TakeoverDevice, list[Command]],
                                               tmp_path: pathlib.Path) -> None:
    import cdp
    from fetch.cli import main

    out, _, _ = corrected
    assert main(["view", str(out), "--out", str(tmp_path / "page"), "--size", "32"]) == 0
    with cdp.open_page(tmp_path / "page" / "index.html", tmp_path) as browser:
        assert browser.wait_for("window.FetchView && FetchView.state.plotted") == "demo_0"
        # two takeovers: two blue stretches on the action plot's timeline, none elsewhere
        assert browser.evaluate("document.querySelectorAll('#plots svg[data-title=action] rect.takeover').length") == 2
        assert browser.evaluate("document.querySelectorAll('#plots rect.takeover').length") == 2
        assert browser.evaluate("FetchView.state.errors") == [] and browser.errors() == []
