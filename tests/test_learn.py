"""fetch.learn on real data: train, resume after a kill, load, act, evaluate on unseen seeds, the CLI."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest

from conftest import StretchCorrector
from fetch.cli import main
from fetch.errors import FetchError
from fetch.learn.evaluate import eval_seeds, wilson
from fetch.testing import operators

TINY = ["--hidden", "32", "--batch-size", "64"]
"""A small network: these tests check the pipeline, the benchmark checks what it learns."""


@pytest.fixture(scope="module")
def reach(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """12 Reach-v2 expert demos (seeds 0-11): 11 in mask/train, 1 in mask/valid."""
    out = tmp_path_factory.mktemp("learn") / "reach"
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "12", "--render", "none",
                 "--max-steps", "50", "--out", str(out)]) == 0
    return out


def _train(dataset: pathlib.Path, out: pathlib.Path, *extra: str) -> int:
    return main(["train", str(dataset), "--out", str(out), *TINY, *extra])


def _checkpoint(torch, run: pathlib.Path) -> dict:  # noqa: ANN001
    return torch.load(run / "checkpoint.pt", weights_only=True)


def _weights(torch, run: pathlib.Path) -> dict:  # noqa: ANN001
    return _checkpoint(torch, run)["model"]


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(bool((a[k] == b[k]).all()) for k in a)


def test_a_trained_policy_loads_and_acts_on_one_or_a_batch(torch, reach: pathlib.Path, tmp_path) -> None:  # noqa: ANN001
    import fetch.learn

    assert _train(reach, tmp_path / "run", "--steps", "200") == 0
    policy = fetch.learn.load(tmp_path / "run")
    assert policy.env_id == "Reach-v2" and policy.seeds == frozenset(range(12))
    env = gym.make("Reach-v2")
    obs, _ = env.reset(seed=123)
    policy.reset()
    action = policy(obs)
    assert action.shape == (4,) and action.dtype == np.float32 and np.all(np.abs(action) <= 1)
    batch = {k: np.stack([v, v, v]) for k, v in obs.items()}
    policy.reset()
    actions = policy(batch)
    assert actions.shape == (3, 4)
    np.testing.assert_allclose(actions[0], action, atol=1e-6)
    with pytest.raises(FetchError, match="batches of 3"):
        policy(obs)  # the batch changed without a reset
    env.close()


def test_the_checkpoint_holds_tensors_and_plain_values_only(torch, reach: pathlib.Path, tmp_path) -> None:  # noqa: ANN001
    assert _train(reach, tmp_path / "run", "--steps", "20", "--checkpoint-every", "10") == 0
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert state["format"] == "gym-fetch-v2/policy" and state["step"] == 20
    assert state["history"]["step"] == [10.0, 20.0] and len(state["history"]["valid_loss"]) == 2
    assert not list((tmp_path / "run").glob(".*tmp")), "no temporary file is left behind"


def test_the_same_seed_gives_the_same_weights_and_another_seed_others(torch, reach: pathlib.Path, tmp_path) -> None:  # noqa: ANN001
    for name, seed in (("a", "3"), ("b", "3"), ("c", "4")):
        assert _train(reach, tmp_path / name, "--steps", "60", "--seed", seed) == 0
    assert _same(_weights(torch, tmp_path / "a"), _weights(torch, tmp_path / "b"))
    assert not _same(_weights(torch, tmp_path / "a"), _weights(torch, tmp_path / "c"))


def test_a_run_killed_mid_training_resumes_to_the_uninterrupted_result(torch, reach: pathlib.Path,
                                                                      tmp_path: pathlib.Path) -> None:  # noqa: ANN001
    args = ["--steps", "1500", "--checkpoint-every", "100", "--seed", "1"]
    assert _train(reach, tmp_path / "whole", *args) == 0
    cmd = [sys.executable, "-m", "fetch.cli", "train", str(reach), "--out", str(tmp_path / "cut"), *TINY, *args]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    for line in proc.stderr:
        if line.startswith("step 100/1500"):
            proc.send_signal(signal.SIGKILL)  # no chance to clean up: only the atomic checkpoint remains
            break
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    cut = torch.load(tmp_path / "cut" / "checkpoint.pt", weights_only=True)
    assert 100 <= cut["step"] < 1500, "the kill landed mid-training"
    assert _train(reach, tmp_path / "cut", *args) == 0
    assert _same(_weights(torch, tmp_path / "whole"), _weights(torch, tmp_path / "cut"))
    whole = torch.load(tmp_path / "whole" / "checkpoint.pt", weights_only=True)
    resumed = torch.load(tmp_path / "cut" / "checkpoint.pt", weights_only=True)
    assert whole["history"] == resumed["history"]


def test_resuming_with_other_settings_is_refused(torch, reach: pathlib.Path, tmp_path, capsys) -> None:  # noqa: ANN001
    assert _train(reach, tmp_path / "run", "--steps", "20") == 0
    capsys.readouterr()
    assert _train(reach, tmp_path / "run", "--steps", "20", "--lr", "0.01") == 2
    err = capsys.readouterr().err.strip()
    assert "other training settings (lr differ)" in err and len(err.splitlines()) == 1


def test_temporal_ensembling_averages_every_chunk_prediction_for_this_step(torch, reach: pathlib.Path,
                                                                           tmp_path) -> None:  # noqa: ANN001
    from fetch.learn.data import acted_actions, flat_obs
    from fetch.learn.runtime import load

    assert _train(reach, tmp_path / "run", "--policy", "mlp-chunk", "--steps", "50", "--chunk", "3") == 0
    policy = load(tmp_path / "run")
    env = gym.make("Reach-v2")
    obs, _ = env.reset(seed=5)
    policy.reset()
    chunks, acted = [], []
    for _ in range(4):
        with torch.no_grad():
            chunks.append(policy.model(torch.from_numpy(policy.normalizer(flat_obs(obs))[None])).numpy()[0])
        acted.append(policy(obs))
        obs, *_ = env.step(acted[-1])
    env.close()
    decay = policy.config.ensemble_decay
    for t in range(4):
        made = list(range(max(0, t - 2), t + 1))  # the chunks that predict step t, oldest first
        weights = np.exp(-decay * np.arange(len(made)))
        expected = sum(w * chunks[s][t - s] for w, s in zip(weights, made, strict=True)) / weights.sum()
        fingers = policy.config.finger_scale, policy.config.finger_span
        np.testing.assert_allclose(acted[t], np.clip(acted_actions(expected, *fingers), -1, 1), atol=1e-5)


def test_eval_act_steps_judges_a_chunk_run_acting_as_asked_and_refuses_what_cannot_be(
        torch, reach: pathlib.Path, tmp_path, capsys) -> None:  # noqa: ANN001
    """`eval --act-steps N` (`Policy.act_every`): a chunk run is evaluated asking its model every N steps, recorded in
    the JSON; beyond its chunk, or for a policy of one action a step, one line naming the choices."""
    from fetch.cli import main
    from fetch.learn.runtime import load

    assert _train(reach, tmp_path / "chunk", "--policy", "mlp-chunk", "--steps", "20", "--chunk", "3") == 0
    policy = load(tmp_path / "chunk")
    assert policy.config.act_steps == 1
    asked = []
    policy.model.register_forward_hook(lambda *_: asked.append(1))
    policy.act_every(3)
    env = gym.make("Reach-v2")
    obs, _ = env.reset(seed=5)
    for _ in range(7):
        obs, *_ = env.step(policy(obs))
    env.close()
    assert len(asked) == 3  # steps 0, 3 and 6
    report = tmp_path / "eval.json"
    assert main(["eval", str(tmp_path / "chunk"), "--episodes", "2", "--act-steps", "2", "--json", str(report)]) == 0
    assert json.loads(report.read_text())["act_steps"] == 2
    capsys.readouterr()
    assert main(["eval", str(tmp_path / "chunk"), "--episodes", "2", "--act-steps", "4"]) == 2
    err = capsys.readouterr().err.strip()
    assert "act_steps must be at most 3" in err and len(err.splitlines()) == 1
    assert _train(reach, tmp_path / "gru", "--policy", "gru", "--steps", "5") == 0
    capsys.readouterr()
    assert main(["eval", str(tmp_path / "gru"), "--episodes", "2", "--act-steps", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert "act_steps is for the chunk kinds (mlp-chunk, cnn-chunk)" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("decay", [0.01, -1.0])
def test_a_chunked_policy_weighs_its_chunks_by_age_as_its_decay_says(torch, decay: float) -> None:  # noqa: ANN001
    """A scripted model whose chunk made at step s predicts 100 s + j for step s + j: acted on at step 3, the
    four chunks' guesses 3, 102, 201, 300 weigh exp(-decay * i), i = 0 for the oldest. A pixel policy's
    default (`PIXEL_ENSEMBLE_DECAY`, below 0) weighs the newest most; ACT's 0.01 nearly alike."""
    from fetch.learn.kinds import PIXEL_ENSEMBLE_DECAY, PolicyConfig, PolicySettings
    from fetch.learn.policies import ChunkActor

    assert PolicySettings.of("cnn-chunk", cameras=("front",)).ensemble_decay == PIXEL_ENSEMBLE_DECAY < 0
    assert PolicySettings.of("mlp-chunk").ensemble_decay == 0.01
    config = PolicyConfig(kind="mlp-chunk", chunk=4, ensemble_decay=decay, obs_size=1)

    def model(x):  # noqa: ANN001, ANN202
        step = float(x[0, 0])
        return torch.arange(4, dtype=torch.float32).reshape(1, 4, 1).repeat(1, 1, 4) + 100 * step

    actor = ChunkActor(config, model)
    for step in range(4):
        acted = actor(torch.full((1, 1), float(step)))
    guesses = np.array([3.0, 102.0, 201.0, 300.0])  # made at steps 0, 1, 2, 3
    weights = np.exp(-decay * np.arange(4))
    np.testing.assert_allclose(acted[0], np.full(4, weights @ guesses / weights.sum()), rtol=1e-6)
    assert (acted[0, 0] > 200) == (decay < 0)  # the newest chunks carry it, or all alike


@pytest.mark.parametrize("act_steps", [2, 3])
def test_a_chunked_policy_predicts_every_act_steps_and_acts_on_the_chunks_covering_the_step(
        torch, act_steps: int) -> None:  # noqa: ANN001
    """`act_steps`: the model is asked every `act_steps` steps only, and each step acts on what the chunks still
    covering it predicted for it, weighed by age: a chunk made at step s (guessing 100 s + j for step s + j)
    is acted on until step s + chunk - 1, then dropped."""
    from fetch.learn.kinds import PolicyConfig
    from fetch.learn.policies import ChunkActor

    decay, chunk = -1.0, 4
    config = PolicyConfig(kind="mlp-chunk", chunk=chunk, ensemble_decay=decay, act_steps=act_steps, obs_size=1)
    asked: list[int] = []

    def model(x):  # noqa: ANN001, ANN202
        asked.append(int(x[0, 0]))
        return torch.arange(4, dtype=torch.float32).reshape(1, 4, 1).repeat(1, 1, 4) + 100 * float(x[0, 0])

    actor = ChunkActor(config, model)
    for step in range(9):
        acted = actor(torch.full((1, 1), float(step)))
        made = [s for s in range(0, step + 1, act_steps) if step - s < chunk]  # oldest first
        weights = np.exp(-decay * np.arange(len(made)))
        guesses = np.array([100.0 * s + step - s for s in made])
        np.testing.assert_allclose(acted[0], np.full(4, weights @ guesses / weights.sum()), rtol=1e-6)
    assert asked == list(range(0, 9, act_steps))
    actor.reset()
    actor(torch.full((1, 1), 50.0))
    assert asked[-1] == 50  # a new episode predicts at once


def test_act_steps_beyond_the_chunk_is_refused_and_old_runs_predict_every_step() -> None:
    """A step no chunk covers cannot be acted on: `act_steps` above `chunk` (or not a whole number >= 1) is one
    error naming it; a checkpoint saved before `act_steps` existed acts as it did, predicting every step."""
    from fetch.errors import FetchError
    from fetch.learn.kinds import PolicyConfig

    for bad in (5, 0, 1.5, True):
        with pytest.raises(FetchError, match="act_steps"):
            PolicyConfig(kind="mlp-chunk", chunk=4, act_steps=bad, obs_size=1)
    assert PolicyConfig.from_dict({"kind": "mlp-chunk", "obs_size": 3}).act_steps == 1


def test_the_chunks_disagreement_is_how_unsure_the_policy_is(torch) -> None:  # noqa: ANN001
    """`ChunkActor.spread`: none at an episode's first step (one chunk covers it), then the standard deviation
    of the chunks' guesses for the step over the hand's entries (the fingers' left out), whatever the decay."""
    from fetch.learn.kinds import PolicyConfig
    from fetch.learn.policies import ChunkActor

    def model(x):  # noqa: ANN001, ANN202  (the chunk made at step s guesses 100 s + j for step s + j; fingers: 0)
        chunk = torch.arange(4, dtype=torch.float32).reshape(1, 4, 1).repeat(1, 1, 4) + 100 * float(x[0, 0])
        chunk[..., 3] = 0.0
        return chunk

    actor = ChunkActor(PolicyConfig(kind="mlp-chunk", chunk=4, ensemble_decay=-1.0, obs_size=1), model)
    actor(torch.zeros((1, 1)))
    assert actor.spread is None
    for step in range(1, 4):
        actor(torch.full((1, 1), float(step)))
    np.testing.assert_allclose(actor.spread, [np.std([3.0, 102.0, 201.0, 300.0])], rtol=1e-6)
    actor.reset()
    assert actor.spread is None


def test_an_ensembles_members_disagreement_is_how_unsure_a_recurrent_policy_is(torch) -> None:  # noqa: ANN001
    """`RecurrentActor.spread`: the members' disagreement on this step's hand action; none for one network."""
    from fetch.learn.kinds import PolicyConfig
    from fetch.learn.policies import RecurrentActor

    class Members:
        def step(self, x, hidden):  # noqa: ANN001, ANN202  (K=3 members, B=2: member k says k on x, 10 k on y)
            out = torch.zeros((3, 2, 1, 4))
            out[:, :, 0, 0] = torch.arange(3.0)[:, None]
            out[:, :, 0, 1] = 10 * torch.arange(3.0)[:, None]
            return out, hidden

    actor = RecurrentActor(PolicyConfig(kind="gru", members=3, obs_size=1), Members())
    actor(torch.zeros((2, 1)))
    np.testing.assert_allclose(actor.spread, np.full(2, np.std([0.0, 10.0, 20.0])), rtol=1e-6)
    single = RecurrentActor(PolicyConfig(kind="gru", obs_size=1), Members())
    single(torch.zeros((2, 1)))
    assert single.spread is None


@pytest.mark.parametrize("kind", ["mlp-chunk", "gru"])
def test_an_ensemble_trains_its_members_apart_and_acts_on_their_mean(torch, reach: pathlib.Path, tmp_path,
                                                                     kind: str) -> None:  # noqa: ANN001
    from fetch.learn.data import acted_actions, flat_obs
    from fetch.learn.kinds import PolicyConfig
    from fetch.learn.policies import build
    from fetch.learn.runtime import load

    assert _train(reach, tmp_path / "run", "--policy", kind, "--steps", "40", "--members", "3") == 0
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    policy = load(tmp_path / "run")
    assert policy.config.members == 3 and len(policy.model.nets) == 3
    first = [w for k, w in state["model"].items() if k.startswith("nets.0.")][0]
    second = state["model"][next(k for k in state["model"] if k.startswith("nets.1."))]
    assert not torch.equal(first, second), "the members start from different weights"
    # Each member, loaded alone, is a network of the kind; the policy acts on their mean.
    alone = PolicyConfig.from_dict({**policy.config.as_dict(), "members": 1})
    members = []
    for i in range(3):
        net = build(alone)
        net.load_state_dict({k.split(".", 2)[2]: v for k, v in state["model"].items() if k.startswith(f"nets.{i}.")})
        members.append(net.eval())
    env = gym.make("Reach-v2")
    obs, _ = env.reset(seed=7)
    policy.reset()
    x = torch.from_numpy(policy.normalizer(flat_obs(obs))[None])
    with torch.no_grad():
        if kind == "gru":
            each = [net.step(x[:, None, :], None)[0][0, 0].numpy() for net in members]
        else:
            each = [net(x)[0, 0].numpy() for net in members]  # the first action of each member's chunk
    fingers = policy.config.finger_scale, policy.config.finger_span
    mean = acted_actions(np.mean(each, axis=0), *fingers)  # the fingers' a[3] as acted
    np.testing.assert_allclose(policy(obs), np.clip(mean, -1, 1), atol=1e-5)
    env.close()


@pytest.mark.parametrize(("setting", "before"), [("members", 1), ("goal_offsets", False), ("finger_scale", 0.0),
                                                   ("finger_span", 1.0), ("act_steps", 1)])
def test_a_checkpoint_from_before_a_setting_existed_loads_as_it_was(torch, reach: pathlib.Path, tmp_path,  # noqa: ANN001
                                                                   setting: str, before: object) -> None:
    """Runs trained before ensembles, goal offsets or the fingers' companded action existed store no such
    setting: they load as one network that sees what it saw and acts as it learnt, and act."""
    from fetch.learn.runtime import load

    assert _train(reach, tmp_path / "run", "--steps", "20") == 0
    path = tmp_path / "run" / "checkpoint.pt"
    state = torch.load(path, weights_only=True)
    del state["policy"][setting]
    torch.save(state, path)
    policy = load(tmp_path / "run")
    assert getattr(policy.config, setting) == before
    env = gym.make("Reach-v2")
    policy.reset()
    assert policy(env.reset(seed=0)[0]).shape == (4,)
    env.close()


def test_a_run_saved_with_other_acting_resumes_and_acts_as_a_new_one(torch, reach: pathlib.Path,
                                                                     tmp_path) -> None:  # noqa: ANN001
    """`act_steps` changes how the network acts, not what it learns (`checkpoint.ACTING_ONLY`): a run interrupted
    before its default changed (saved without it, or with another) resumes, and goes on as a new run acts; a
    setting that shapes learning still refuses (`test_resuming_with_other_settings_is_refused`)."""
    args = ("--policy", "mlp-chunk", "--chunk", "3")
    assert _train(reach, tmp_path / "run", *args, "--steps", "20") == 0
    path = tmp_path / "run" / "checkpoint.pt"
    for saved in (3, None):
        state = torch.load(path, weights_only=True)
        if saved is None:
            del state["policy"]["act_steps"]
        else:
            state["policy"]["act_steps"] = saved
        state["step"] = 10  # as if stopped halfway
        torch.save(state, path)
        assert _train(reach, tmp_path / "run", *args, "--steps", "20") == 0
        resumed = torch.load(path, weights_only=True)
        assert resumed["step"] == 20 and resumed["policy"]["act_steps"] == 1


@pytest.mark.parametrize("kind", ["mlp-chunk", "gru"])
def test_a_policy_with_goal_offsets_sees_the_goal_relative_to_the_achieved_goal_and_the_hand(
        torch, reach: pathlib.Path, tmp_path, kind: str) -> None:  # noqa: ANN001
    from fetch.learn.data import acted_actions, flat_obs
    from fetch.learn.runtime import load

    assert _train(reach, tmp_path / "plain", "--policy", kind, "--steps", "20") == 0
    assert _train(reach, tmp_path / "run", "--policy", kind, "--steps", "20", "--goal-offsets") == 0
    plain, policy = load(tmp_path / "plain"), load(tmp_path / "run")
    assert policy.config.goal_offsets and not plain.config.goal_offsets
    assert policy.config.obs_size == plain.config.obs_size + 6
    env = gym.make("Reach-v2")
    obs, _ = env.reset(seed=3)
    # Built by hand from the observation dict: the state, the goal, goal - achieved, goal - grip.
    goal, achieved, grip = obs["desired_goal"], obs["achieved_goal"], obs["observation"][:3]
    x = np.concatenate([obs["observation"], goal, goal - achieved, goal - grip]).astype(np.float32)
    np.testing.assert_allclose(flat_obs(obs, goal_offsets=True), x, atol=1e-6)
    with torch.no_grad():
        net = torch.from_numpy(policy.normalizer(x)[None])
        expected = (policy.model.step(net[:, None, :], None)[0][0, 0] if kind == "gru" else policy.model(net)[0, 0])
    policy.reset()
    fingers = policy.config.finger_scale, policy.config.finger_span
    expected = acted_actions(expected.numpy(), *fingers)  # the fingers' a[3] as acted
    np.testing.assert_allclose(policy(obs), np.clip(expected, -1, 1), atol=1e-5)
    env.close()


def test_a_recurrent_policy_trains_and_acts(torch, reach: pathlib.Path, tmp_path) -> None:  # noqa: ANN001
    from fetch.learn.runtime import load

    assert _train(reach, tmp_path / "run", "--policy", "gru", "--steps", "30", "--seq-len", "4") == 0
    policy = load(tmp_path / "run")
    env = gym.make("Reach-v2")
    obs, _ = env.reset(seed=0)
    policy.reset()
    first = [policy(obs) for _ in range(5)]  # the same observation: the hidden state makes actions differ,
    assert not np.allclose(first[0], first[1])  # until the state restarts at seq_len
    np.testing.assert_allclose(first[4], first[0], atol=1e-6)
    env.close()


def test_eval_runs_on_seeds_the_dataset_never_used(torch, reach: pathlib.Path, tmp_path, capsys) -> None:  # noqa: ANN001
    from fetch.learn.evaluate import evaluate
    from fetch.learn.runtime import load

    assert _train(reach, tmp_path / "run", "--steps", "300") == 0
    policy = load(tmp_path / "run")
    result = evaluate(policy, 5, envs=2, seed_start=10)  # three waves, the last one short
    assert result.seeds == (12, 13, 14, 15, 16), "the dataset's seeds 0-11 are skipped"
    assert len(result.success) == 5 and all(1 <= n <= 50 for n in result.first_success)
    assert all(n == 50 for n, ok in zip(result.first_success, result.ever, strict=True) if not ok)
    capsys.readouterr()
    assert main(["eval", str(tmp_path / "run"), "--episodes", "5", "--envs", "3", "--seed-start", "10",
                 "--json", str(tmp_path / "eval.json")]) == 0
    out = capsys.readouterr().out
    assert "95% CI" in out and "mean episode length" in out
    saved = json.loads((tmp_path / "eval.json").read_text())
    assert saved["seeds"] == [12, 13, 14, 15, 16] and saved["success"] == list(result.success), \
        "the same seeds give the same outcomes, however many envs step at once"
    assert saved["ever"] == list(result.ever)  # per episode, what lerobot-eval's successes are compared with


def test_eval_in_the_batched_vector_env_gives_what_separate_envs_give(torch, reach: pathlib.Path, tmp_path,
                                                                      monkeypatch) -> None:  # noqa: ANN001
    from fetch.learn import evaluate as ev
    from fetch.learn.runtime import load
    from fetch.vector import FetchVectorEnv, has_batch

    assert _train(reach, tmp_path / "run", "--steps", "300") == 0
    policy = load(tmp_path / "run")
    built: list[gym.vector.VectorEnv] = []
    make = ev.make_vector_env
    monkeypatch.setattr(ev, "make_vector_env", lambda *a: built.append(make(*a)) or built[-1])
    batched = ev.evaluate(policy, 6, envs=4)
    assert isinstance(built[0], FetchVectorEnv) == has_batch(), "the batched env wherever mujoco can thread it"
    monkeypatch.setattr(ev, "make_vector_env", lambda env_id, count, kwargs, steps: gym.vector.SyncVectorEnv(
        [lambda: gym.make(env_id, max_episode_steps=steps, **kwargs) for _ in range(count)]))
    separate = ev.evaluate(policy, 6, envs=4)
    assert batched == separate and 0 < len(batched.success) == 6


def test_eval_writes_videos(torch, reach: pathlib.Path, tmp_path) -> None:  # noqa: ANN001
    pytest.importorskip("av")
    assert _train(reach, tmp_path / "run", "--steps", "20") == 0
    assert main(["eval", str(tmp_path / "run"), "--episodes", "2", "--video", str(tmp_path / "videos"),
                 "--videos", "1"]) == 0
    from fetch.dataset.render.video import read_video

    (path,) = (tmp_path / "videos").glob("*.mp4")
    frames, fps = read_video(path)
    assert path.name == "Reach-v2_seed1000000.mp4" and len(frames) == 51 and fps == 25


def test_the_fingers_action_is_learnt_companded_and_acted_as_recorded() -> None:
    """The fingers' servo range (+-finger_scale) spans [-1, 1], the squeeze (-1) goes to -2, the hand's
    three numbers are left as they are, and acting undoes it exactly; finger_scale 0 leaves actions alone;
    a span scales the learnt a[3]."""
    from fetch.learn.data import acted_actions, learnt_actions
    from fetch.learn.kinds import FINGER_SCALE, FINGER_SPAN

    a = np.array([[0.3, -0.7, 1.0, a3] for a3 in (-1.0, -0.05, -0.02, 0.0, 0.01, 0.05, 0.5, 1.0)], np.float32)
    learnt = learnt_actions(a, FINGER_SCALE)
    np.testing.assert_array_equal(learnt[:, :3], a[:, :3])
    np.testing.assert_allclose(learnt[:, 3], [-2.0, -1.0, -0.4, 0.0, 0.2, 1.0, 1.0 + 0.45 / 0.95, 2.0], atol=1e-6)
    assert np.all(np.diff(learnt[:, 3]) > 0)  # order kept: a policy's mean of two is between them
    np.testing.assert_allclose(acted_actions(learnt, FINGER_SCALE), a, atol=1e-6)
    assert learnt_actions(a, 0.0) is a and acted_actions(a, 0.0) is a
    # the default span: the servo range over +-0.5, the squeeze at -1, as a[3] weighs recorded
    half = learnt_actions(a, FINGER_SCALE, FINGER_SPAN)
    np.testing.assert_allclose(half[:, 3], FINGER_SPAN * learnt[:, 3], atol=1e-6)
    assert FINGER_SPAN == 0.5 and half[0, 3] == -1.0
    np.testing.assert_allclose(acted_actions(half, FINGER_SCALE, FINGER_SPAN), a, atol=1e-6)


def test_eval_seeds_skip_the_excluded_ones() -> None:
    assert eval_seeds(4, {0, 2, 3}, start=0) == [1, 4, 5, 6]
    assert eval_seeds(0, set()) == []


def test_the_wilson_interval_matches_published_values() -> None:
    # Newcombe (1998), table I: 0/10 -> 0-0.2775; 10/10 -> 0.7225-1; 81/263 -> 0.2553-0.3662.
    for (k, n), expected in (((0, 10), (0.0, 0.2775)), ((10, 10), (0.7225, 1.0)), ((81, 263), (0.2553, 0.3662))):
        np.testing.assert_allclose(wilson(k, n), expected, atol=1e-4)


def test_a_policy_drives_a_collection_session(torch, reach: pathlib.Path, tmp_path) -> None:  # noqa: ANN001
    from fetch.dataset import open_dataset
    from fetch.learn.device import PolicyDevice
    from fetch.teleop.session import CollectConfig, Session

    assert _train(reach, tmp_path / "run", "--steps", "300") == 0
    config = CollectConfig(env_id="Reach-v2", out=str(tmp_path / "demos"), episodes=1, max_steps=50,
                           device="expert", render="none", keep_failures=True, seed=500)
    env = gym.make("Reach-v2", max_episode_steps=50)
    device = PolicyDevice(env, tmp_path / "run")
    assert device.name == "policy"
    Session(config, device, log=lambda _: None).run()
    with open_dataset(tmp_path / "demos") as ds:
        (name,) = ds.demo_names
        assert int(ds.attrs(name)["num_samples"]) > 0
    with pytest.raises(FetchError, match="trained on Reach-v2, not Push-v2"):
        PolicyDevice(gym.make("Push-v2"), tmp_path / "run")


def test_collect_with_takeover_runs_the_policy_until_the_pad_moves(torch, reach, tmp_path, pad) -> None:  # noqa: ANN001
    """`gym-fetch collect --device takeover --policy RUN`: with the (virtual) pad left alone the policy
    drives every step, and each step is labelled so."""
    from fetch.dataset import open_dataset, validate

    assert _train(reach, tmp_path / "run", "--steps", "300") == 0
    out = tmp_path / "demos"
    assert main(["collect", "--env", "Reach-v2", "--device", "takeover", "--policy", str(tmp_path / "run"),
                 "--out", str(out), "--episodes", "1", "--max-steps", "30", "--keep-failures", "--render", "none",
                 "--control-hz", "0", "--seed", "500"]) == 0
    with open_dataset(out) as ds:
        assert validate(ds) == []
        (name,) = ds.demo_names
        arrays = ds.arrays(name)
        assert ds.attrs(name)["device"] == "takeover"
        assert not arrays["intervention"].any()
        np.testing.assert_array_equal(arrays["policy_actions"], arrays["actions"])
    with pytest.raises(SystemExit):
        main(["collect", "--env", "Reach-v2", "--device", "takeover", "--takeover-with", "expert"])


def test_the_window_says_how_unsure_the_driving_policy_is(torch, reach, tmp_path) -> None:  # noqa: ANN001
    """A chunk policy as a device notes in the HUD how far its chunks' guesses for the step lie apart (from its
    second step: one chunk covers the first), and the takeover device shows it beside who drives."""
    import re

    from fetch.learn.device import PolicyDevice
    from fetch.learn.takeover import TakeoverDevice

    assert _train(reach, tmp_path / "run", "--policy", "mlp-chunk", "--steps", "30") == 0
    env = gym.make("Reach-v2")
    device = TakeoverDevice(PolicyDevice(env, tmp_path / "run"), StretchCorrector())
    obs, _ = env.reset(seed=900)
    device.reset()
    statuses = []
    for _ in range(3):
        command = device.poll(obs)
        statuses.append(command.status)
        obs, *_ = env.step(command.action)
    assert "unsure" not in statuses[0] and statuses[0].startswith("the policy drives")
    assert all(re.search(r"the policy drives   takeovers 0   unsure \d+ mm", s) for s in statuses[1:]), statuses


def test_train_from_a_run_goes_on_with_the_corrections(torch, reach, tmp_path) -> None:  # noqa: ANN001
    """`train DEMOS CORRECTED --from RUN`: the run's policy, weights and normalisation go on learning from the
    demos plus the stretches a person drove (each `--correction-weight` times); stopped, it resumes."""
    from fetch.dataset import open_dataset
    from fetch.learn.data import load_many
    from fetch.learn.device import PolicyDevice
    from fetch.learn.takeover import TakeoverDevice
    from fetch.teleop.session import CollectConfig, Session

    assert _train(reach, tmp_path / "run", "--steps", "200") == 0
    corrected = tmp_path / "corrected"
    env = gym.make("Reach-v2", max_episode_steps=40)
    device = TakeoverDevice(PolicyDevice(env, tmp_path / "run"), StretchCorrector())
    config = CollectConfig(env_id="Reach-v2", out=str(corrected), episodes=3, max_steps=40, device="takeover",
                           render="none", control_hz=0, keep_failures=True, seed=700)
    Session(config, device, env=env, log=lambda _: None).run()
    with open_dataset(corrected) as ds:
        person = sum(int(ds.arrays(n)["intervention"].sum()) for n in ds.demo_names)
    assert person > 0
    demos = load_many([reach, corrected], correction_weight=3)
    stretches = [e for e in demos.train if e.corrected]
    assert stretches and len(stretches) % 3 == 0 and sum(len(e.actions) for e in stretches) <= 3 * person
    assert sum(not e.corrected for e in demos.train) == 11 and demos.seeds >= {700, 701, 702}

    argv = ["train", str(reach), str(corrected), "--from", str(tmp_path / "run"), "--out", str(tmp_path / "again"),
            "--correction-weight", "3", "--steps", "60", "--checkpoint-every", "30", "--batch-size", "64"]
    assert main(argv) == 0
    state = _checkpoint(torch, tmp_path / "again")
    base = _checkpoint(torch, tmp_path / "run")
    assert state["source"]["from"]["step"] == 200 and state["policy"] == base["policy"]
    assert torch.equal(state["norm"]["mean"], base["norm"]["mean"]), "the run's input normalisation goes on"
    assert any(name.endswith("(takeover 1)") for name in state["source"]["train_demos"])
    assert main(argv) == 0  # finished: run again, it is left as it is
    assert int(_checkpoint(torch, tmp_path / "again")["step"]) == 60
    assert main([*argv[:-6], "--policy", "gru"]) == 2  # --from keeps the run's policy


@pytest.mark.parametrize("argv, message", [
    (["--policy", "gru", "--chunk", "3"], "--chunk is for --policy mlp-chunk"),
    (["--demos", "50"], "has only 11 demos in mask/train"),
    (["--steps", "0"], "--steps must be a whole number >= 1"),
    (["--lr", "nan"], "--lr must be a finite number > 0"),
    (["--epochs", "0"], "--epochs must be a whole number >= 1"),
    (["--members", "0"], "policy members must be a whole number >= 1"),
])
def test_bad_training_arguments_get_one_line_errors(torch, reach, tmp_path, capsys, argv, message) -> None:  # noqa: ANN001
    assert main(["train", str(reach), "--out", str(tmp_path / "run"), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def test_bad_inputs_get_one_line_errors(torch, reach, tmp_path, capsys) -> None:  # noqa: ANN001
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    (tmp_path / "empty").mkdir()
    cases = [
        (["train", str(tmp_path / "nothing"), "--out", str(tmp_path / "r")], "no such file"),
        (["eval", str(tmp_path / "empty")], "is not a run directory"),
        (["eval", str(tmp_path / "junk.pt")], "is not a readable policy checkpoint"),
    ]
    for argv, message in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1, err
    assert _train(reach, tmp_path / "run", "--steps", "5") == 0
    capsys.readouterr()
    for argv, message in ((["--episodes", "0"], "--episodes must be a whole number >= 1"),
                          (["--video", str(tmp_path), "--camera", "nose"], "unknown camera 'nose'")):
        assert main(["eval", str(tmp_path / "run"), *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1, err


def test_a_checkpoint_with_pickled_code_is_refused(torch, tmp_path) -> None:  # noqa: ANN001
    from fetch.learn.checkpoint import read

    run = tmp_path / "run"
    run.mkdir()
    torch.save({"format": "gym-fetch-v2/policy", "hook": os.system}, run / "checkpoint.pt")
    with pytest.raises(FetchError, match="not a readable policy checkpoint"):
        read(run)


@pytest.mark.skipif(importlib.util.find_spec("torch") is not None, reason="torch is installed here")
def test_without_torch_train_says_how_to_install_it(reach: pathlib.Path, tmp_path, capsys) -> None:  # noqa: ANN001
    assert main(["train", str(reach), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith('pip install ".[train]" (in the gym-fetch-v2 source tree)') and len(err.splitlines()) == 1


def test_from_the_pad_to_a_policy(torch, pad, tmp_path: pathlib.Path) -> None:  # noqa: ANN001
    """Demos recorded through SDL's game-controller path train a policy that then runs end to end."""
    import dataclasses

    from fetch.dataset import open_dataset
    from fetch.experts import make_expert
    from fetch.teleop.gamepad import GamepadConfig, GamepadDevice
    from fetch.teleop.session import CollectConfig, Session

    config = CollectConfig(env_id="Reach-v2", out=str(tmp_path / "human"), device="gamepad", render="none",
                           control_hz=0, success_hold_steps=3, max_steps=100, episodes=4)
    # A person steering the grip site to the goal: Reach's expert on the pad, a steady hand (fetch.testing.operators).
    steady = dataclasses.replace(operators.STANDIN, noise=0.0)
    operator = operators.Operator(pad, GamepadDevice(GamepadConfig(deadzone=0.02)), make_expert("Reach-v2"), steady)
    Session(config, operator, log=lambda _: None).run()
    with open_dataset(tmp_path / "human") as ds:
        assert len(ds.demo_names) == 4 and {ds.attrs(n)["device"] for n in ds.demo_names} == {"gamepad"}
    assert _train(tmp_path / "human", tmp_path / "run", "--steps", "100") == 0
    assert main(["eval", str(tmp_path / "run"), "--episodes", "4", "--envs", "4"]) == 0


def test_train_takes_the_steps_measured_for_the_task_unless_told(torch, reach: pathlib.Path, tmp_path,  # noqa: ANN001
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    import fetch.learn
    from fetch.learn.recipes import RECIPES, Training, task_training

    assert task_training("Bin-pick-v2").steps == 10000 and task_training("Reach-v2").steps == Training().steps == 5000
    # A measured exception, small enough for a test:
    monkeypatch.setitem(RECIPES, "Reach-v2", Training(steps=30))
    assert _train(reach, tmp_path / "auto") == 0
    assert fetch.learn.load(tmp_path / "auto").trained_steps == 30
    assert _train(reach, tmp_path / "told", "--steps", "20") == 0
    assert fetch.learn.load(tmp_path / "told").trained_steps == 20


def test_every_task_trains_a_registered_kind_and_every_kind_is_complete(torch) -> None:  # noqa: ANN001
    from fetch.learn.kinds import KINDS, PolicySettings, kind
    from fetch.learn.policies import Kind, implementation
    from fetch.learn.recipes import task_training
    from fetch.tasks import REGISTRATIONS

    for k in KINDS:
        assert isinstance(implementation(k.name), Kind), k.name
        assert set(k.own) <= {f.name for f in dataclasses.fields(PolicySettings)}, k.name
        seen = {"cameras": ("front",)} if k.inputs == "pixels" else {}  # a pixel kind needs a camera
        assert all(getattr(PolicySettings.of(k.name, **seen), n) == v for n, v in k.defaults.items())
    for r in REGISTRATIONS:
        recipe = task_training(r.env_id)
        assert kind(recipe.policy).name == recipe.policy, r.env_id
        assert r.task.mirrors or not recipe.mirror, f"{r.env_id}: auto mirrors symmetric tasks only"
        assert recipe.chunk is None or "chunk" in kind(recipe.policy).own, r.env_id


def test_the_python_api_trains_what_the_command_trains(torch, reach: pathlib.Path, tmp_path) -> None:  # noqa: ANN001
    """`train(dataset, out, TrainRequest(...))` decides its defaults where the CLI does: the same settings and
    weights."""
    from fetch.learn.settings import TrainRequest
    from fetch.learn.train import train

    assert main(["train", str(reach), "--out", str(tmp_path / "cli"), "--steps", "20"]) == 0  # not TINY: defaults
    result = train(reach, tmp_path / "api", TrainRequest(steps=20), show_progress=False, log=lambda _: None)
    cli, api = _checkpoint(torch, tmp_path / "cli"), _checkpoint(torch, tmp_path / "api")
    assert cli["policy"] == api["policy"] == {**result.plan.policy.as_dict(), "obs_size": api["policy"]["obs_size"],
                                              "image_size": 0, "image_quality": ""}
    assert cli["train"] == api["train"]
    assert all(torch.equal(cli["model"][k], api["model"][k]) for k in cli["model"])


def test_auto_trains_the_policy_measured_best_for_the_task(torch, reach: pathlib.Path, tmp_path) -> None:  # noqa: ANN001
    from fetch.learn.data import velocity_columns
    from fetch.learn.recipes import task_training
    from fetch.learn.runtime import load

    assert task_training("Drawer-close-v2").policy == "mlp-chunk" and task_training("Reach-v2").policy == "gru"
    assert _train(reach, tmp_path / "run", "--steps", "20") == 0  # --policy auto
    assert load(tmp_path / "run").config.kind == "gru"
    push = tmp_path / "push"
    assert main(["collect", "--env", "Push-v2", "--device", "expert", "--episodes", "3", "--render", "none",
                 "--max-steps", "50", "--out", str(push)]) == 0
    assert _train(push, tmp_path / "push-run", "--steps", "5") == 0
    auto = load(tmp_path / "push-run").config
    assert auto.members == 5 and auto.goal_offsets and auto.chunk == 1
    assert auto.blind == velocity_columns(gym.make("Push-v2").unwrapped.observation_layout)
    assert _checkpoint(torch, tmp_path / "push-run")["train"]["mirror"]  # Training(mirror=True) on Push
    assert _train(push, tmp_path / "push-one", "--steps", "5", "--members", "1", "--no-goal-offsets",
                  "--no-mirror", "--velocities", "--chunk", "10") == 0
    one = load(tmp_path / "push-one").config  # flags override auto
    assert one.members == 1 and not one.goal_offsets and one.blind == () and one.chunk == 10
    assert not _checkpoint(torch, tmp_path / "push-one")["train"]["mirror"]


def test_mirror_learns_from_each_demo_and_its_mirror_image(torch, reach: pathlib.Path, tmp_path,  # noqa: ANN001
                                                           capsys) -> None:
    assert _train(reach, tmp_path / "plain", "--steps", "30", "--policy", "mlp-chunk") == 0
    assert _train(reach, tmp_path / "mirror", "--steps", "30", "--policy", "mlp-chunk", "--mirror") == 0
    assert "11 Reach-v2 demos and their mirror images" in capsys.readouterr().out
    plain, mirror = _checkpoint(torch, tmp_path / "plain"), _checkpoint(torch, tmp_path / "mirror")
    assert mirror["train"]["mirror"] and not plain["train"]["mirror"]
    # Normalisation statistics come from both: the mean hand y is now the plane's (the start's).
    start_y = gym.make("Reach-v2").reset(seed=0)[0]["observation"][1]
    assert abs(float(mirror["norm"]["mean"][1]) - start_y) < 1e-4 < abs(float(plain["norm"]["mean"][1]) - start_y)
    assert not _same(plain["model"], mirror["model"])


def test_mirror_on_a_task_that_is_not_symmetric_is_refused_before_anything_is_written(
        torch, tmp_path, capsys) -> None:  # noqa: ANN001
    slide = tmp_path / "slide"
    assert main(["collect", "--env", "Slide-v2", "--device", "expert", "--episodes", "3", "--render", "none",
                 "--max-steps", "50", "--out", str(slide)]) == 0
    capsys.readouterr()
    assert main(["train", str(slide), "--out", str(tmp_path / "run"), "--mirror", *TINY]) == 2
    err = capsys.readouterr().err.strip()
    assert "Slide-v2 is not symmetric" in err and "Reach-v2, Push-v2, PickPlace-v2" in err, err
    assert len(err.splitlines()) == 1 and not (tmp_path / "run").exists()


@pytest.mark.parametrize("style", ["standin", "rests", "slow", "pauses", "regrasp", "gripper", "side", "person"])
def test_every_operators_style_goes_the_whole_path(torch, pad, style: str, tmp_path: pathlib.Path,  # noqa: ANN001
                                                   capsys) -> None:  # noqa: ANN001
    """Pad demos by each stand-in operator (fetch.testing.operators) -> generate -> train -> eval, tiny: the
    commands are the same for every style; the run knows the horizon its demos need, and eval reports
    both it and the registered one."""
    from fetch.learn.data import load_demos
    from fetch.learn.runtime import load

    human = operators.record(pad, "PickPlace-v2", style, tmp_path / "human", 3, seed=11)
    generated = tmp_path / "generated"
    assert main(["generate", "--source", str(human), "--out", str(generated), "--demos", "6", "--workers", "1"]) == 0
    assert _train(generated, tmp_path / "run", "--steps", "30", "--policy", "mlp-chunk") == 0
    policy = load(tmp_path / "run")
    assert policy.horizon == load_demos(generated).horizon >= 50
    assert main(["eval", str(tmp_path / "run"), "--episodes", "3", "--envs", "3", "--json",
                 str(tmp_path / "eval.json")]) == 0
    result = json.loads((tmp_path / "eval.json").read_text())
    assert result["horizon"] == policy.horizon and result["registered_horizon"] == 50
    if style == "slow":  # the person's own demos, slower than 50 steps: a run on them is given their time
        assert _train(human, tmp_path / "direct", "--steps", "20", "--policy", "mlp-chunk") == 0
        direct = load(tmp_path / "direct")
        assert direct.horizon > 50
        capsys.readouterr()
        assert main(["eval", str(tmp_path / "direct"), "--episodes", "2", "--envs", "2"]) == 0
        out = capsys.readouterr().out
        assert f"at step {direct.horizon} (the policy's horizon, from its demos); at the registered step 50" in out


def test_eval_video_without_pyav_says_so_before_running_anything(torch, reach: pathlib.Path, tmp_path,  # noqa: ANN001
                                                                 monkeypatch: pytest.MonkeyPatch, capsys) -> None:  # noqa: ANN001
    from fetch.learn import evaluate as ev

    assert _train(reach, tmp_path / "run", "--steps", "5") == 0
    monkeypatch.setitem(sys.modules, "av", None)  # import av raises ImportError
    ran: list[int] = []
    monkeypatch.setattr(ev, "evaluate", lambda *a, **k: ran.append(1))
    capsys.readouterr()
    assert main(["eval", str(tmp_path / "run"), "--episodes", "2", "--video", str(tmp_path / "videos")]) == 2
    err = capsys.readouterr().err.strip()
    assert "writing video needs PyAV" in err and 'pip install ".[video]"' in err and len(err.splitlines()) == 1
    assert not ran and not (tmp_path / "videos").exists()


def test_wrong_turns_between_datasets_and_runs_get_one_line_answers(torch, reach: pathlib.Path, tmp_path,  # noqa: ANN001
                                                                    capsys) -> None:  # noqa: ANN001
    """eval on a dataset (its folder or its file) says it is a dataset and how to train on it; train into
    the dataset's own folder is refused before anything is written."""
    for target in (reach, reach / "demos.hdf5"):
        capsys.readouterr()
        assert main(["eval", str(target)]) == 2
        err = capsys.readouterr().err.strip()
        assert f"{target} is a dataset, not a run: train a policy on it with `gym-fetch train {target}" in err
        assert len(err.splitlines()) == 1 and "Weights only" not in err
    before = sorted(p.name for p in reach.rglob("*"))
    for out in (reach, reach / "run"):
        capsys.readouterr()
        assert _train(reach, out, "--steps", "5") == 2
        err = capsys.readouterr().err.strip()
        assert f"--out {out} is inside the dataset" in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in reach.rglob("*")) == before


def test_train_says_what_it_is_about_to_do_at_once_and_how_long_it_takes(torch, reach: pathlib.Path,  # noqa: ANN001
                                                                          tmp_path, capsys,  # noqa: ANN001
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from fetch.learn import data

    read = data.load_demos
    monkeypatch.setattr(data, "load_demos", lambda path, images=False: (time.sleep(1.5), read(path, images))[1])
    capsys.readouterr()
    assert _train(reach, tmp_path / "run", "--steps", "40", "--policy", "mlp-chunk") == 0
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == f"reading {reach} ...", "a read that takes a while says so"
    assert lines[1].startswith("training mlp-chunk on ") and "for steps 1-40, batch " in lines[1]
    assert lines[2].startswith("step 10/40: ") and lines[2].endswith("minutes to go")


@pytest.mark.parametrize("kind", ["mlp-chunk", "gru"])
def test_a_policy_without_velocities_does_not_see_them(torch, reach: pathlib.Path, tmp_path, kind: str,  # noqa: ANN001
                                                       capsys) -> None:  # noqa: ANN001
    """`--no-velocities`: the observation's velocity entries (Reach: the grip site's and the fingers') are
    left out of what the policy reads, in training and acting; anything in their place, NaN included,
    gives the same actions. The run says so, records it, and a resume with velocities on is refused."""
    from fetch.learn.data import velocity_columns
    from fetch.learn.runtime import load

    run = tmp_path / "run"
    assert _train(reach, run, "--steps", "20", "--policy", kind, "--no-velocities", "--checkpoint-every", "10") == 0
    assert "not seeing velocities" in capsys.readouterr().out
    env = gym.make("Reach-v2")
    layout = env.unwrapped.observation_layout
    velocities = velocity_columns(layout)
    assert velocities == tuple(i for name in ("grip_velp", "gripper_vel") for i in range(layout[name].start,
                                                                                           layout[name].stop))
    assert tuple(_checkpoint(torch, run)["policy"]["blind"]) == velocities
    policy = load(run)
    obs, _ = env.reset(seed=123)
    hidden = {k: v.copy() for k, v in obs.items()}
    hidden["observation"][list(velocities)] = np.nan
    seen = {k: v.copy() for k, v in obs.items()}
    seen["observation"][list(velocities)] += 0.5
    actions = []
    for o in (obs, hidden, seen):
        policy.reset()
        actions.append(policy(o))
    assert np.isfinite(actions[0]).all()
    np.testing.assert_array_equal(actions[0], actions[1])
    np.testing.assert_array_equal(actions[0], actions[2])
    # The same command with velocities on differs from the run's settings: a resume refuses it.
    assert _train(reach, run, "--steps", "30", "--policy", kind, "--velocities") == 2
    assert "blind" in capsys.readouterr().err
