"""The real consumer: lerobot's own `LeRobotDataset` loads `gym-fetch export --to lerobot`.

Runs only where lerobot is installed (0.4.4 on Python 3.11 and 0.6 on 3.12, each in its own virtualenv:
scripts/make_lerobot_venv.sh, scripts/make_lerobot06_venv.sh), and is skipped in the main test environment.
"""

from __future__ import annotations

import pathlib
import shutil
from collections.abc import Mapping

import numpy as np
import pytest

pytest.importorskip("lerobot", reason="lerobot is not installed (it has its own virtualenv, .venv-lerobot)")
torch = pytest.importorskip("torch")

from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402

from fetch.dataset import open_dataset  # noqa: E402
from fetch.dataset.exports import lerobot  # noqa: E402
from fetch.dataset.exports.export import export_lerobot  # noqa: E402
from fetch.dataset.render.frames import StateRenderer  # noqa: E402
from fetch.dataset.schema import meant_actions  # noqa: E402
from fetch.learn.takeover import TakeoverDevice  # noqa: E402
from fetch.teleop.devices import Command  # noqa: E402
from fetch.teleop.session import CollectConfig, Session  # noqa: E402

SIZE = 64
CAMERAS = ["front", "wrist"]
REPO_ID = "test/fetch_reach"


@pytest.fixture(scope="module")
def demos(reach_demos: pathlib.Path) -> dict[str, object]:
    with open_dataset(reach_demos) as ds:
        names = list(ds.demo_names)
        return {"arrays": [ds.arrays(n) for n in names], "env_id": ds.env_id, "env_kwargs": ds.env_kwargs}


def load(root: pathlib.Path, **kwargs: object) -> LeRobotDataset:
    return LeRobotDataset(REPO_ID, root=root, **kwargs)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 10 * np.log10(255**2 / max(mse, 1e-12))


def check_dataset(dataset: LeRobotDataset, demos: dict[str, object]) -> None:
    arrays: list[dict[str, np.ndarray]] = demos["arrays"]  # type: ignore[assignment]
    lengths = [len(a["actions"]) for a in arrays]
    starts = np.concatenate([[0], np.cumsum(lengths)])
    assert len(dataset) == dataset.num_frames == sum(lengths)
    assert dataset.num_episodes == len(arrays) and dataset.fps == 25
    for e in range(len(arrays)):
        episode = dataset.meta.episodes[e]
        assert (episode["dataset_from_index"], episode["dataset_to_index"]) == (starts[e], starts[e + 1])
    with StateRenderer(str(demos["env_id"]), demos["env_kwargs"], SIZE, SIZE) as renderer:  # type: ignore[arg-type]
        for e, a in enumerate(arrays):
            for t in range(lengths[e]):
                item = dataset[int(starts[e]) + t]
                assert (item["episode_index"].item(), item["frame_index"].item()) == (e, t)
                assert item["index"].item() == starts[e] + t
                assert item["task"] == "move the gripper to the goal"
                assert np.array_equal(item["observation.state"].numpy(), a["obs/observation"][t].astype(np.float32))
                assert np.array_equal(item["observation.environment_state"].numpy(),
                                      a["obs/desired_goal"][t].astype(np.float32))
                # What a policy imitates is the expert's clean action (DART); the applied one beside it.
                assert np.array_equal(item["action"].numpy(), meant_actions(a)[t])
                assert np.array_equal(item["executed_action"].numpy(), a["actions"][t])
                assert item["next.reward"].item() == a["rewards"][t]
                assert item["next.done"].item() == bool(a["dones"][t])
                assert item["next.success"].item() == bool(a["is_success"][t])
                assert item["timestamp"].item() == pytest.approx(t / 25, abs=1e-6)
                for camera in CAMERAS:
                    decoded = (item[f"observation.images.{camera}"].permute(1, 2, 0).numpy() * 255).round()
                    fresh = renderer.frame(a["states"][t], camera)
                    assert decoded.shape == fresh.shape
                    assert psnr(decoded, fresh) > 30, (e, t, camera, psnr(decoded, fresh))


def test_lerobot_loads_the_export(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                  demos: dict[str, object]) -> None:
    root = tmp_path / "ds"
    export_lerobot(reach_demos, REPO_ID, root, cameras=CAMERAS, image_size=SIZE)
    dataset = load(root)
    check_dataset(dataset, demos)
    assert list(dataset.meta.tasks.index) == ["move the gripper to the goal"]
    assert set(dataset.meta.video_keys) == {f"observation.images.{c}" for c in CAMERAS}
    assert dataset.meta.stats["action"]["mean"].shape == (4,)
    # A LeRobot policy learns `action` alone: the applied `executed_action` is not taken for another one.
    from lerobot.configs.types import FeatureType

    try:  # lerobot 0.6 moved it
        from lerobot.utils.feature_utils import dataset_to_policy_features
    except ImportError:  # 0.4
        from lerobot.datasets.utils import dataset_to_policy_features

    policy_features = dataset_to_policy_features(dataset.meta.features)
    assert [k for k, f in policy_features.items() if f.type is FeatureType.ACTION] == ["action"]
    assert dataset.meta.stats["observation.images.front"]["mean"].shape == (3, 1, 1)


def test_many_files_and_action_chunks(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                      demos: dict[str, object], monkeypatch: pytest.MonkeyPatch) -> None:
    """Tiny file limits put every episode in files of its own (new chunk/file indices, video
    timestamps from 0 again); an ACT-style action chunk is padded at each episode's end."""
    monkeypatch.setattr(lerobot, "DATA_FILE_MB", 1e-6)
    monkeypatch.setattr(lerobot, "VIDEO_FILE_MB", 1e-6)
    root = tmp_path / "ds"
    export_lerobot(reach_demos, REPO_ID, root, cameras=CAMERAS, image_size=SIZE)
    arrays: list[dict[str, np.ndarray]] = demos["arrays"]  # type: ignore[assignment]
    assert len(list((root / "data").rglob("*.parquet"))) == len(arrays)
    assert len(list((root / "videos/observation.images.front").rglob("*.mp4"))) == len(arrays)
    check_dataset(load(root), demos)
    chunked = load(root, delta_timestamps={"action": [0.0, 0.04, 0.08]})
    last = len(arrays[0]["actions"]) - 1
    item = chunked[last - 1]  # the second-to-last step of episode 0: one step of the chunk is past its end
    assert item["action_is_pad"].tolist() == [False, False, True]
    assert np.array_equal(item["action"][:2].numpy(), meant_actions(arrays[0])[last - 1:last + 1])


def test_default_out_is_where_lerobot_looks() -> None:
    from lerobot.utils.constants import HF_LEROBOT_HOME

    assert lerobot.lerobot_home() == HF_LEROBOT_HOME


class Drift:
    """A policy that pushes the hand along +x whatever it sees (the policy device's interface)."""

    name = "policy"

    def reset(self) -> None:
        pass

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        return Command(np.array([0.6, 0.0, 0.0, 1.0], np.float32))

    def close(self) -> None:
        pass


class Person:
    """Takes the arm at tick 6 for 6 ticks, lets go, and takes it again from tick 31 to steer to the goal."""

    name = "gamepad"

    def __init__(self) -> None:
        self.tick = 0

    def reset(self) -> None:
        self.tick = 0

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        self.tick += 1
        steer = 6 <= self.tick < 12 or self.tick > 30
        move = np.clip((obs["desired_goal"] - obs["achieved_goal"]) / 0.05, -1, 1) * steer
        return Command(np.append(move, 1.0).astype(np.float32), touched=steer)

    def close(self) -> None:
        pass


@pytest.fixture(scope="module")
def corrected(reach_demos: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """The two expert demos and an attempt a person corrected twice (`--device takeover`), in one dataset."""
    out = tmp_path_factory.mktemp("corrected") / "demos"
    shutil.copytree(reach_demos, out)
    config = CollectConfig(env_id="Reach-v2", out=str(out), device="takeover", render="none", control_hz=0,
                           max_steps=50, episodes=1)
    summary = Session(config, TakeoverDevice(Drift(), Person()), log=lambda text: None).run()
    assert summary.saved == 1, summary.describe()
    return out


def test_lerobot_reads_who_drove(corrected: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """The takeover labels: every frame's `intervention` and `policy_action` as the HDF5 holds them (false
    and the action itself in the demos nobody corrected), and the statistics LeRobot normalises with."""
    root = tmp_path / "ds"
    export_lerobot(corrected, REPO_ID, root, cameras=[])
    with open_dataset(corrected) as ds:
        arrays = [ds.arrays(n) for n in ds.demo_names]
    assert sum("intervention" in a for a in arrays) == 1 and arrays[-1]["intervention"].any()
    flags = np.concatenate([a.get("intervention", np.zeros(len(a["actions"]), np.uint8)) for a in arrays])
    proposed = np.concatenate([a.get("policy_actions", a["actions"]) for a in arrays]).astype(np.float32)
    dataset = load(root)
    assert len(dataset) == len(flags)
    assert dataset.meta.features["intervention"]["dtype"] == "bool"
    got = [dataset[i] for i in range(len(dataset))]
    assert [bool(item["intervention"].item()) for item in got] == flags.astype(bool).tolist()
    assert np.array_equal(np.stack([item["policy_action"].numpy() for item in got]), proposed)
    stats = dataset.meta.stats
    for key, values in (("intervention", flags[:, None]), ("policy_action", proposed),
                        ("action", np.concatenate([meant_actions(a) for a in arrays]))):
        x = values.astype(np.float64)
        for stat, want in (("min", x.min(0)), ("max", x.max(0)), ("mean", x.mean(0)), ("std", x.std(0))):
            np.testing.assert_allclose(np.asarray(stats[key][stat], np.float64), want, rtol=1e-6, atol=1e-7,
                                       err_msg=f"{key} {stat}")
        assert int(np.asarray(stats[key]["count"]).item()) == len(x)
