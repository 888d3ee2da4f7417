"""A run's checkpoint is a stranger's file: every field is checked before use, and a crafted or garbled one is
refused in one line naming the file, never with a traceback, a hang, a huge allocation or an import."""

from __future__ import annotations

import argparse
import io
import math
import os
import pathlib
import shutil
import subprocess
import sys
from collections.abc import Callable
from typing import Any

import pytest

torch = pytest.importorskip("torch")

from fetch.cli import main  # noqa: E402
from fetch.errors import FetchError  # noqa: E402
from test_corrupt_inputs import snapshot  # noqa: E402

TRAINING = ["--steps", "3", "--hidden", "8", "--batch-size", "16", "--checkpoint-every", "1000"]
"""A tiny run: these tests check what is refused, not what is learnt."""


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> tuple[pathlib.Path, pathlib.Path]:
    """Three Reach-v2 expert demos and a run trained on them for a few steps."""
    root = tmp_path_factory.mktemp("hostile")
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "3", "--render", "none",
                 "--max-steps", "50", "--out", str(root / "demos")]) == 0
    assert main(["train", str(root / "demos"), "--out", str(root / "run"), *TRAINING]) == 0
    return root / "demos", root / "run"


def _set(*keys: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """Set `state[keys[0]][keys[1]]... = value`."""
    def edit(state: dict[str, Any]) -> None:
        inner = state
        for key in keys[:-1]:
            inner = inner[key]
        inner[keys[-1]] = value
    return edit


def _norm(edit: Callable[[Any], Any], name: str = "mean") -> Callable[[dict[str, Any]], None]:
    def change(state: dict[str, Any]) -> None:
        state["norm"][name] = edit(state["norm"][name].clone())
    return change


def _nan_at_0(t: Any) -> Any:
    t[0] = math.nan
    return t


def _zero_at_0(t: Any) -> Any:
    t[0] = 0.0
    return t


def _first_weight(state: dict[str, Any]) -> None:
    name = next(iter(state["model"]))
    state["model"][name] = torch.zeros(3, 3)


CASES: dict[str, tuple[Callable[[dict[str, Any]], None], str]] = {
    "horizon_huge": (_set("horizon", value=10**12), "horizon"),
    "horizon_negative": (_set("horizon", value=-5), "horizon"),
    "horizon_zero": (_set("horizon", value=0), "horizon"),
    "horizon_fraction": (_set("horizon", value=1.5), "horizon"),
    "horizon_text": (_set("horizon", value="x"), "horizon"),
    "hidden_huge": (_set("policy", "hidden", value=10**9), "hidden"),
    "layers_huge": (_set("policy", "layers", value=10**6), "layers"),
    "members_huge": (_set("policy", "members", value=10**6), "members"),
    "chunk_huge": (_set("policy", "chunk", value=10**9), "chunk"),
    "seq_len_huge": (_set("policy", "seq_len", value=10**9), "seq_len"),
    "obs_size_wrong": (_set("policy", "obs_size", value=14), "inputs"),
    "kind_unknown": (_set("policy", "kind", value="os:system"), "policy"),
    "kind_list": (_set("policy", "kind", value=["gru"]), "policy"),
    "finger_scale_text": (_set("policy", "finger_scale", value="x"), "finger_scale"),
    "norm_wrong_shape": (_norm(lambda t: t[:5]), "norm mean"),
    "norm_2d": (_norm(lambda t: t[None]), "norm mean"),
    "norm_nan": (_norm(_nan_at_0), "NaN"),
    "norm_zero_std": (_norm(_zero_at_0, "std"), "std"),
    "norm_not_tensor": (_set("norm", "std", value=[1.0] * 13), "norm std"),
    "env_kwargs_not_json": (_set("source", "env_kwargs", value="not json"), "JSON"),
    "env_kwargs_task": (_set("source", "env_kwargs", value='{"task": "push"}'), "'task'"),
    "env_kwargs_bogus": (_set("source", "env_kwargs", value='{"bogus": 1}'), "'bogus'"),
    "env_kwargs_list": (_set("source", "env_kwargs", value="[]"), "env_kwargs"),
    "env_kwargs_value": (_set("source", "env_kwargs", value='{"hide_goal": 1}'), "hide_goal"),
    "env_kwargs_size": (_set("source", "env_kwargs", value='{"image_size": 1000000}'), "image_size"),
    "env_id_this": (_set("source", "env_id", value="this:Reach-v2"), "this:Reach-v2"),
    "env_id_venv": (_set("source", "env_id", value="venv.__main__:Reach-v2"), "venv.__main__:Reach-v2"),
    "env_id_unknown": (_set("source", "env_id", value="Reach-v9"), "Reach-v9"),
    "seeds_float": (lambda s: s.__setitem__("seeds", s["seeds"].double()), "seeds"),
    "seeds_2d": (lambda s: s.__setitem__("seeds", s["seeds"][None]), "seeds"),
    "step_negative": (_set("step", value=-1), "step"),
    "train_steps_huge": (_set("train", "steps", value=10**12), "steps"),
    "train_unknown": (_set("train", "bogus", value=1), "bogus"),
    "weights_wrong": (_first_weight, "weights"),
    "weights_missing": (lambda s: s.__setitem__("model", {}), "weights"),
    "rng_wrong": (_set("rng", value=torch.zeros(3, dtype=torch.uint8)), "rng"),
    "history_wrong": (_set("history", value={"step": "x"}), "history"),
    "source_tensor": (_set("source", "dataset", value=torch.zeros(2)), "source"),
}


def _crafted(run: pathlib.Path, to: pathlib.Path, case: str) -> pathlib.Path:
    """A copy of `run` whose checkpoint is changed as `case` says."""
    shutil.copytree(run, to)
    state = torch.load(to / "checkpoint.pt", weights_only=True)
    CASES[case][0](state)
    torch.save(state, to / "checkpoint.pt")
    return to


def _gym_fetch(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, "-m", "fetch.cli", *args], capture_output=True, text=True, timeout=30,
                          env=env)


def _refused(done: subprocess.CompletedProcess[str], command: str, file: pathlib.Path) -> str:
    """The one line a refusal prints, checked: exit 2, no traceback, the file named."""
    said = f"exit {done.returncode}; stdout {done.stdout!r}; stderr {done.stderr!r}"
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and "Traceback" not in done.stdout + done.stderr, said
    assert len(lines) == 1 and lines[0].startswith(f"gym-fetch {command}: error: "), said
    assert str(file) in lines[0], said
    return lines[0]


def test_the_run_as_trained_loads(made: tuple[pathlib.Path, pathlib.Path], tmp_path: pathlib.Path) -> None:
    """The checks pass on what `train` writes (and on a copy of it rewritten by torch.save, as the cases are)."""
    import fetch.learn

    run = _crafted(made[1], tmp_path / "run", "horizon_zero")
    shutil.copy(made[1] / "checkpoint.pt", run / "checkpoint.pt")
    policy = fetch.learn.load(run)
    assert policy.env_id == "Reach-v2" and policy.horizon == 50 and policy.config.hidden == 8
    state = torch.load(run / "checkpoint.pt", weights_only=True)
    torch.save(state, run / "checkpoint.pt")
    assert fetch.learn.load(run).trained_steps == 3


@pytest.mark.parametrize("case", list(CASES))
def test_a_crafted_checkpoint_is_refused_in_one_line(made: tuple[pathlib.Path, pathlib.Path], tmp_path: pathlib.Path,
                                                     case: str) -> None:
    import fetch.learn

    run = _crafted(made[1], tmp_path / "run", case)
    with pytest.raises(FetchError) as caught:
        fetch.learn.load(run)
    message = str(caught.value)
    assert "\n" not in message and len(message) < 1000, message
    assert str(run / "checkpoint.pt") in message and CASES[case][1] in message, message


class Settings(argparse.Namespace):
    """What a pickle checkpoint holds beside its tensors: an object, which unpickling would construct."""


def test_a_pickle_checkpoint_is_refused_saying_why(made: tuple[pathlib.Path, pathlib.Path],
                                                   tmp_path: pathlib.Path) -> None:
    import fetch.learn

    run = tmp_path / "run"
    shutil.copytree(made[1], run)
    state = torch.load(run / "checkpoint.pt", weights_only=True)
    torch.save({**state, "args": Settings(hidden=8)}, run / "checkpoint.pt")
    with pytest.raises(FetchError) as caught:
        fetch.learn.load(run)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{run / 'checkpoint.pt'} is not a weights-only checkpoint"), \
        message
    assert "Settings" in message and "can run code when loaded" in message and "refused" in message, message
    done = _gym_fetch("eval", str(run), "--episodes", "1")
    assert "weights-only" in _refused(done, "eval", run / "checkpoint.pt")


@pytest.mark.parametrize("content", [b"", b"\x00garbage" * 20, b"PK\x03\x04 not a zip"])
def test_a_garbled_file_is_refused_in_one_line(made: tuple[pathlib.Path, pathlib.Path], tmp_path: pathlib.Path,
                                               content: bytes) -> None:
    import fetch.learn

    run = tmp_path / "run"
    shutil.copytree(made[1], run)
    (run / "checkpoint.pt").write_bytes(content)
    with pytest.raises(FetchError) as caught:
        fetch.learn.load(run)
    assert "\n" not in str(caught.value) and str(run / "checkpoint.pt") in str(caught.value), str(caught.value)


def test_a_fifo_for_the_checkpoint_is_refused_not_waited_on(tmp_path: pathlib.Path) -> None:
    import fetch.learn

    run = tmp_path / "run"
    run.mkdir()
    os.mkfifo(run / "checkpoint.pt")
    with pytest.raises(FetchError, match="not a regular file"):
        fetch.learn.load(run)


EVAL_CASES = ["horizon_huge", "horizon_negative", "hidden_huge", "norm_wrong_shape", "env_kwargs_not_json",
              "env_kwargs_task", "env_kwargs_bogus", "env_id_this", "env_id_venv", "seeds_float", "weights_wrong"]


@pytest.mark.parametrize("case", EVAL_CASES)
def test_eval_refuses_a_crafted_checkpoint_in_one_line(made: tuple[pathlib.Path, pathlib.Path],
                                                       tmp_path: pathlib.Path, case: str) -> None:
    run = _crafted(made[1], tmp_path / "run", case)
    done = _gym_fetch("eval", str(run), "--episodes", "1")
    line = _refused(done, "eval", run / "checkpoint.pt")
    assert CASES[case][1] in line, line
    assert "The Zen of Python" not in done.stdout + done.stderr  # `this` was never imported


@pytest.mark.parametrize("case", ["horizon_huge", "env_kwargs_bogus", "env_id_this"])
def test_collecting_with_a_crafted_policy_is_refused_in_one_line(made: tuple[pathlib.Path, pathlib.Path],
                                                                 tmp_path: pathlib.Path, case: str) -> None:
    run = _crafted(made[1], tmp_path / "run", case)
    done = _gym_fetch("collect", "--env", "Reach-v2", "--device", "policy", "--policy", str(run), "--episodes", "1",
                      "--render", "none", "--out", str(tmp_path / "demos"))
    _refused(done, "collect", run / "checkpoint.pt")
    assert "The Zen of Python" not in done.stdout + done.stderr


@pytest.mark.parametrize("case", ["hidden_huge", "norm_nan", "env_kwargs_task", "train_steps_huge"])
def test_training_from_a_crafted_run_is_refused_in_one_line(made: tuple[pathlib.Path, pathlib.Path],
                                                            tmp_path: pathlib.Path, case: str) -> None:
    run = _crafted(made[1], tmp_path / "run", case)
    done = _gym_fetch("train", str(made[0]), "--from", str(run), "--out", str(tmp_path / "again"))
    _refused(done, "train", run / "checkpoint.pt")
    assert not (tmp_path / "again").exists()


def _garbled_optimizer(state: dict[str, Any]) -> None:
    first = next(iter(state["optimizer"]["state"].values()))
    first["exp_avg"] = torch.zeros(2, 2)


def _optimizer_setting(state: dict[str, Any]) -> None:
    state["optimizer"]["param_groups"][0]["betas"] = "xx"


@pytest.mark.parametrize("edit", [_garbled_optimizer, _optimizer_setting, CASES["weights_wrong"][0],
                                  CASES["rng_wrong"][0], CASES["history_wrong"][0]])
def test_resuming_a_crafted_run_is_refused_in_one_line(made: tuple[pathlib.Path, pathlib.Path],
                                                       tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
                                                       edit: Callable[[dict[str, Any]], None]) -> None:
    """`train ... --out RUN` where RUN holds a checkpoint resumes it: what it reads there is checked too, the
    optimizer's state among it. (The run asks for more steps than it took, so it would go on.)"""
    run = tmp_path / "run"
    shutil.copytree(made[1], run)
    state = torch.load(run / "checkpoint.pt", weights_only=True)
    state["train"]["steps"] = 6
    edit(state)
    buffer = io.BytesIO()
    torch.save(state, buffer)
    (run / "checkpoint.pt").write_bytes(buffer.getvalue())
    argv = ["train", str(made[0]), "--out", str(run), "--steps", "6", *TRAINING[2:]]
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if "error:" in line]  # a slow read may say "reading ..." first
    assert len(errors) == 1 and err.strip().endswith(errors[0]) and "Traceback" not in err, err
    assert str(run / "checkpoint.pt") in errors[0], err
    assert (run / "checkpoint.pt").read_bytes() == buffer.getvalue(), "the refused checkpoint was rewritten"


# -- the run folder's names: links where a tool reads or writes the checkpoint --------------------------

@pytest.mark.parametrize("plant", ["tmp_link", "checkpoint_link_out"])
def test_a_run_folder_s_links_are_never_written_through_nor_read_out_of(
        made: tuple[pathlib.Path, pathlib.Path], tmp_path: pathlib.Path, plant: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`run/.checkpoint.pt.tmp -> v6.txt`, then `train ... --out run` (resume) overwrote v6.txt with the
    checkpoint; `run/checkpoint.pt` a link to a file outside was read as the run's."""
    demos, trained = made
    run, victim = tmp_path / "run", tmp_path / "victim"
    victim.mkdir()
    (victim / "v6.txt").write_text("version 6\n")
    if plant == "tmp_link":  # in a folder without a checkpoint yet: the training writes one
        run.mkdir()
        (run / ".checkpoint.pt.tmp").symlink_to(victim / "v6.txt")
    else:
        shutil.copytree(trained, run)
        shutil.move(str(run / "checkpoint.pt"), victim / "checkpoint.pt")
        (run / "checkpoint.pt").symlink_to(victim / "checkpoint.pt")
    before = snapshot(victim)
    capsys.readouterr()
    code = main(["train", str(demos), "--out", str(run), *TRAINING])
    err = capsys.readouterr().err
    assert snapshot(victim) == before
    if plant == "tmp_link":
        assert code == 0 and not (run / "checkpoint.pt").is_symlink(), err
    else:
        assert code == 2 and "outside" in err and len(err.strip().splitlines()) == 1, err
        with pytest.raises(FetchError, match="outside"):
            from fetch.learn import load

            load(run)


# -- every case against every tool that opens a run, in this process (a refusal takes milliseconds) -----

RUN_TOOLS: dict[str, list[str]] = {
    "eval": ["eval", "{run}", "--episodes", "1"],
    "collect_policy": ["collect", "--env", "Reach-v2", "--device", "policy", "--policy", "{run}", "--episodes", "1",
                       "--render", "none", "--out", "{t}/demos"],
    "collect_takeover": ["collect", "--env", "Reach-v2", "--device", "takeover", "--policy", "{run}",
                         "--takeover-with", "gamepad", "--episodes", "1", "--render", "none", "--out", "{t}/demos"],
    "train_from": ["train", "{demos}", "--from", "{run}", "--out", "{t}/again", *TRAINING],
    "train_resume": ["train", "{demos}", "--out", "{run}", *TRAINING],
}
"""Each tool that reads a run's checkpoint; a new one joins by one line."""


@pytest.mark.parametrize("tool", list(RUN_TOOLS))
@pytest.mark.parametrize("case", list(CASES))
def test_every_tool_refuses_every_crafted_checkpoint_in_one_line(
        made: tuple[pathlib.Path, pathlib.Path], tmp_path: pathlib.Path, case: str, tool: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Nothing written anywhere, nothing imported, exit 2 and one line naming the checkpoint, within 30 s."""
    import time

    demos, trained = made
    run = _crafted(trained, tmp_path / "run", case)
    argv = [a.format(run=run, demos=demos, t=tmp_path) for a in RUN_TOOLS[tool]]
    imported, before, given = set(sys.modules), snapshot(tmp_path), snapshot(demos)
    capsys.readouterr()
    start = time.perf_counter()
    try:
        code = main(argv)
    except BaseException as e:  # noqa: BLE001 (any escape is the failure this test is about)
        pytest.fail(f"gym-fetch {' '.join(argv)} raised {e!r} instead of a one-line error")
    seconds = time.perf_counter() - start
    out, err = capsys.readouterr()
    lines = [line for line in err.strip().splitlines() if not line.startswith("collecting ")]  # collect's banner
    said = f"exit {code}; stdout {out[-300:]!r}; stderr {err!r}"
    assert code == 2 and "Traceback" not in out + err, said
    assert len(lines) == 1 and lines[0].startswith(f"gym-fetch {argv[0]}: error: "), said
    assert str(run / "checkpoint.pt") in lines[0] and CASES[case][1] in lines[0], said
    assert snapshot(tmp_path) == before and snapshot(demos) == given, "a refused run wrote something"
    assert {"this", "venv.__main__"} & (set(sys.modules) - imported) == set(), said
    assert seconds < 30, f"{seconds:.0f} s: {said}"
