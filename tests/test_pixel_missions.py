"""A tiny pixel mission per stand-in style (`benchmarks/mission.py --inputs pixels`, in seconds): the stand-in's
demos through the virtual pad, `generate` rendering the front and wrist cameras, `train --inputs pixels` and
`eval` on unseen seeds, the policy given the observation with the objects' state hidden."""

from __future__ import annotations

import json
import pathlib
from typing import Any

import numpy as np
import pytest

from conftest import hide_objects, objects_state
from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.dataset.habits import dataset_flags, layout_of
from fetch.testing import operators

ENV = "Bin-pick-v2"
"""A grasp into a bin: the block's place and the walls beside it are in the images, not in what the policy reads."""
CAMERAS = ("front", "wrist")
SIZE = 32
"""[px] the images' side: small, so a mission takes seconds; the benchmark measures what the default 64 px learns."""
TINY = ["--steps", "5", "--hidden", "32", "--batch-size", "16", "--checkpoint-every", "10"]
EPISODES = 2

HABITS: dict[str, str | None] = {"standin": None, "person": "idle", "pauses": "idle", "slow": None,
                                 "regrasp": "regrasp"}
"""The styles the mission is run with, and the flag (`gym-fetch info`) their pad demos show at this seed."""
HALF_STICK = 0.6
"""`slow` pushes the stick 0.45-0.55 of the way (noise 0.05): no arm action beyond this."""


class HiddenState:
    """Eval's vector env, giving the policy each observation with the objects' state NaN (every entry but the
    robot's own readings, and the achieved goal); a twin of the policy acts on the whole observation beside it:
    a step whose action is not finite, or not the twin's, depended on what the policy must not see."""

    def __init__(self, vec: Any, hidden: np.ndarray, twin: Any) -> None:
        self.vec, self.hidden, self.twin = vec, hidden, twin
        self.whole: dict[str, np.ndarray] = {}
        self.steps = 0

    def _hide(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self.whole = {k: np.array(v, copy=True) for k, v in obs.items()}
        return hide_objects(obs, self.hidden)

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        obs, info = self.vec.reset(**kwargs)
        self.twin.reset()
        return self._hide(obs), info

    def step(self, action: np.ndarray) -> tuple[Any, ...]:
        assert np.isfinite(action).all() and np.array_equal(action, self.twin(self.whole)), \
            f"step {self.steps}: the policy's action depended on the objects' state, shown to it as NaN"
        self.steps += 1
        obs, *rest = self.vec.step(action)
        return (self._hide(obs), *rest)

    def close(self) -> None:
        self.vec.close()


@pytest.mark.parametrize("style", sorted(HABITS))
def test_a_tiny_pixel_mission_by_each_style(torch, pad, style: str, tmp_path: pathlib.Path,  # noqa: ANN001
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """2 pad demos by the stand-in, 4 generated with 32 px images, 5 training steps, 2 episodes of eval: each
    stage gets what the one before made, and the policy sees the cameras, its own readings and the goal only.
    No success rate: the tiny policy is not meant to succeed."""
    import fetch.learn
    from fetch.learn import evaluate
    human = operators.record(pad, ENV, style, tmp_path / "human", 2, seed=0)
    with open_dataset(human) as ds:
        pad_demos = set(ds.demo_names)
        assert len(pad_demos) == 2
        for name in pad_demos:
            attrs, arrays = ds.attrs(name), ds.arrays(name)
            assert attrs["device"] == "gamepad" and attrs["success"] and arrays["is_success"][-1] > 0, name
            if style == "slow":
                assert np.abs(arrays["actions"][:, :3]).max() < HALF_STICK, "the stick at half"
        flags = {f.kind for found in dataset_flags(ds).values() for f in found}
    assert HABITS[style] is None or HABITS[style] in flags, f"{style}'s habit is not in its demos: {flags}"

    generated = tmp_path / "generated"
    assert main(["generate", "--source", str(human), "--out", str(generated), "--demos", "4", "--workers", "1",
                 "--cameras", ",".join(CAMERAS), "--image-size", str(SIZE), "--image-quality", "fast"]) == 0
    with open_dataset(generated) as ds:
        assert (ds.layout.cameras, ds.layout.image_size, ds.layout.image_quality) == (CAMERAS, SIZE, "fast")
        assert len(ds.demo_names) == 4
        seeds = set()
        for name in ds.demo_names:
            attrs, arrays = ds.attrs(name), ds.arrays(name)
            assert attrs["success"] and set(json.loads(attrs["source_demos"])) <= pad_demos, name
            steps = int(attrs["num_samples"])
            for camera in CAMERAS:
                for side in ("obs", "next_obs"):
                    images = arrays[f"{side}/{camera}_image"]
                    assert images.dtype == np.uint8 and images.shape == (steps, SIZE, SIZE, 3), (name, camera)
                    assert not np.array_equal(images[0], images[-1]), f"{name} {camera}: the scene does not move"
            seeds.add(int(attrs["seed"]))

    run = tmp_path / "run"
    assert main(["train", str(generated), "--out", str(run), "--inputs", "pixels", *TINY]) == 0
    policy = fetch.learn.load(run)
    config = policy.config
    assert (config.kind, config.cameras, config.image_size, config.image_quality) == ("cnn-chunk", CAMERAS, SIZE,
                                                                                      "fast")
    assert policy.image_keys == ("front_image", "wrist_image") and policy.env_id == ENV
    assert policy.seeds == seeds and policy.trained_steps == 5
    layout = layout_of(ENV)
    assert layout is not None
    hidden = objects_state(layout)
    assert set(np.flatnonzero(hidden).tolist()) <= set(config.blind), "it reads the objects' state"

    made: list[HiddenState] = []
    real = evaluate.make_vector_env

    def hiding(*args: Any) -> HiddenState:
        made.append(HiddenState(real(*args), hidden, fetch.learn.load(run)))
        return made[-1]

    monkeypatch.setattr(evaluate, "make_vector_env", hiding)
    result = tmp_path / "eval.json"
    assert main(["eval", str(run), "--episodes", str(EPISODES), "--envs", str(EPISODES), "--json", str(result)]) == 0
    outcome = json.loads(result.read_text())
    assert outcome["env_id"] == ENV and outcome["episodes"] == EPISODES and len(outcome["success"]) == EPISODES
    assert not set(outcome["seeds"]) & seeds, "evaluated on the data's seeds"
    (env,) = made
    assert env.steps == outcome["horizon"] == policy.horizon > 0, "every step acted on the state hidden"
