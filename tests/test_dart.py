"""DART recording: the expert (and generation with --noise) executes a perturbed action, labels the clean
one as `expert_actions`; demos still replay exactly, and training learns the labels."""

from __future__ import annotations

import json
import pathlib

import gymnasium as gym
import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.dataset.replay.check import check_demo
from fetch.dataset.schema import OBS_KEYS, check_arrays
from fetch.experts import make_expert
from fetch.learn.data import load_demos


def _collect(out: pathlib.Path, *more: str, env_id: str = "PickPlace-v2", episodes: int = 3) -> pathlib.Path:
    assert main(["collect", "--env", env_id, "--device", "expert", "--episodes", str(episodes), "--render", "none",
                 "--out", str(out), *more]) == 0
    return out


@pytest.fixture(scope="module")
def dart(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Three PickPlace-v2 demos from `collect --device expert` with its defaults."""
    return _collect(tmp_path_factory.mktemp("dart") / "pick")


def test_the_expert_by_default_records_noisy_actions_with_its_clean_ones_beside_them(dart: pathlib.Path) -> None:
    with open_dataset(dart) as ds:
        assert ds.settings["stop_on_success"] is False and ds.settings["max_steps"] == 50, \
            "the expert's demos run to the task's horizon"
        expert = make_expert(ds.env_id)
        for name in ds.demo_names:
            arrays = ds.arrays(name)
            assert arrays["actions"].shape == arrays["expert_actions"].shape == (50, 4)
            assert not check_arrays(arrays, ds.layout, 50)
            noise = arrays["actions"] - arrays["expert_actions"]
            assert 0.05 < float(noise[:, :3].std()) < 0.15, "the executed action carries N(0, 0.1) noise"
            assert 0.05 < float(noise[:, 3].std()) < 0.15, "and on the fingers, a[3]"
            # The labels are what the expert says at the states the noisy arm visited.
            expert.reset()
            said = [expert({k: arrays[f"obs/{k}"][t] for k in OBS_KEYS}) for t in range(50)]
            assert np.allclose(np.clip(said, -1, 1), arrays["expert_actions"], atol=1e-6)
            assert check_demo(ds, name).exact, "the executed actions replay the demo"


def test_training_learns_the_clean_labels(dart: pathlib.Path) -> None:
    demos = load_demos(dart)
    with open_dataset(dart) as ds:
        for episode in demos.train:
            assert np.array_equal(episode.actions, ds.arrays(episode.name)["expert_actions"])


def test_no_noise_records_the_plain_expert_and_stop_on_success_still_ends_early(tmp_path: pathlib.Path) -> None:
    out = _collect(tmp_path / "plain", "--expert-noise", "0", "--stop-on-success")
    with open_dataset(out) as ds:
        expert = make_expert(ds.env_id)
        for name in ds.demo_names:
            arrays = ds.arrays(name)
            assert "expert_actions" not in arrays
            assert len(arrays["actions"]) < 50, "it ended once success had held"
            expert.reset()
            said = [expert({k: arrays[f"obs/{k}"][t] for k in OBS_KEYS}) for t in range(len(arrays["actions"]))]
            assert np.allclose(np.clip(said, -1, 1), arrays["actions"], atol=1e-6)


def test_the_fingers_noise_can_be_set_apart(tmp_path: pathlib.Path) -> None:
    """--expert-finger-noise 0.005 perturbs the fingers' target as many metres as the hand's (a[3] is metres); the
    hand's noise is the same draws either way."""
    plain = _collect(tmp_path / "plain", episodes=1)
    metres = _collect(tmp_path / "metres", "--expert-finger-noise", "0.005", episodes=1)
    with open_dataset(plain) as a, open_dataset(metres) as b:
        before, now = a.arrays(a.demo_names[0]), b.arrays(b.demo_names[0])
        assert 0.002 < float((now["actions"] - now["expert_actions"])[:, 3].std()) < 0.008
        first = before["actions"][0, :3] - before["expert_actions"][0, :3]
        assert np.allclose(first, now["actions"][0, :3] - now["expert_actions"][0, :3], atol=1e-6)


@pytest.mark.parametrize(("flag", "value"), [("--expert-noise", "-0.1"), ("--expert-noise", "nan"),
                                             ("--expert-finger-noise", "-1")])
def test_a_bad_noise_is_refused_in_one_line(flag: str, value: str, tmp_path: pathlib.Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "1", "--render", "none",
                 "--out", str(tmp_path / "d"), flag, value]) == 2
    err = capsys.readouterr().err
    assert f"{flag} must be a finite std >= 0" in err and "Traceback" not in err


def test_labels_of_the_wrong_shape_are_a_problem(dart: pathlib.Path) -> None:
    with open_dataset(dart) as ds:
        arrays = ds.arrays(ds.demo_names[0])
        arrays["expert_actions"] = arrays["expert_actions"][:-1]
        assert check_arrays(arrays, ds.layout, 50) == ["expert_actions has shape (49, 4), expected (50, 4)"]


def test_generation_with_noise_labels_the_planned_action(dart: pathlib.Path, tmp_path: pathlib.Path) -> None:
    out = tmp_path / "gen"
    assert main(["generate", "--source", str(dart), "--out", str(out), "--demos", "2", "--workers", "1",
                 "--noise", "0.1"]) == 0
    with open_dataset(out) as ds:
        env = gym.make(ds.env_id)
        for name in ds.demo_names:
            arrays = ds.arrays(name)
            noise = arrays["actions"] - arrays["expert_actions"]
            assert float(np.abs(noise[:, :3]).max()) > 0.05
            # The fingers are perturbed too (as the expert device does), so their labels show the servo's correction.
            assert float(np.abs(noise[:, 3]).max()) > 0.05, "fingers: no noise"
            assert check_demo(ds, name, env.unwrapped).exact


def test_another_device_adds_to_an_expert_dataset_under_its_settings(tmp_path: pathlib.Path) -> None:
    out = _collect(tmp_path / "d", env_id="Reach-v2", episodes=1)
    script = tmp_path / "idle.json"
    script.write_text(json.dumps([{"action": [0, 0, 0, 0]}] * 80 + [{"quit": True}]))
    assert main(["collect", "--env", "Reach-v2", "--device", "scripted", "--scripted-json", str(script),
                 "--keep-failures", "--episodes", "1", "--render", "none", "--out", str(out)]) == 0
    with open_dataset(out) as ds:
        assert ds.settings["max_steps"] == 50 and ds.settings["stop_on_success"] is False
        assert ds.masks()["failed"] == ["demo_1"] and len(ds.arrays("demo_1")["actions"]) == 50, \
            "the scripted attempt ran to the dataset's 50 steps, not a new session's 500"
