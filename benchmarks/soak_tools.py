"""Soak every tool: each stopped at a random moment by SIGKILL, SIGTERM, a terminal's Ctrl-C (SIGINT to
the process group), a double Ctrl-C, or a stdout that is closed or full; then checked.

Per round: the tool runs in its own process group on a fresh copy of a small PickPlace dataset (12
expert demos) or into a fresh output, is stopped after a random 0.5-6 s, and must

- exit within 10 s of the stop (a tool that finished first counts as a correct result; a tool whose
  stdout was closed or full is then sent SIGTERM, as it may rightly go on without one),
- with 0, 128 + the signal, minus the signal (killed by a second Ctrl-C while Python winds down), or a
  one-line error (1 or 2: a closed or full stdout), and no traceback;
- leave no worker process running 10 s later;
- leave its input exactly as it was (read-only tools) or valid (tools that edit it);
- leave its output valid, or absent, and no temporary file in $TMPDIR that its next run does not
  remove (the rounds of a tool share one $TMPDIR).

Prints one table of tools by stop, each cell "passed/rounds" with the failures listed below it.

    python -m benchmarks.soak_tools --rounds 3 --out /tmp/soak-tools
    python -m benchmarks.soak_tools --tools collect,render-obs --stops group-int,double-int --rounds 10

`train` and `eval` run with the torch venv's Python (`--train-python`, default .venv-train/bin/python).
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import os
import pathlib
import random
import shutil
import signal
import subprocess
import sys
import time

from fetch.testing.procs import alive, children

STOPS = ("kill", "term", "group-int", "double-int", "closed-stdout", "full-stdout")
GRACE = 10.0
"""[s] how long a stopped tool may take to exit, and its workers after it."""


def tool_commands(data: pathlib.Path, out: pathlib.Path, run_dir: pathlib.Path) -> dict[str, list[str]]:
    """Each tool's arguments after `gym-fetch`: `data` is a copy of the fixture it may edit, `out` a
    path that does not exist yet, `run_dir` a trained run."""
    return {
        "collect": ["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "100000", "--render", "none",
                    "--control-hz", "0", "--out", str(out)],
        "collect-cameras": ["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "100000",
                            "--render", "none", "--control-hz", "0", "--cameras", "front", "--image-size", "32",
                            "--out", str(out)],
        "generate": ["generate", "--source", str(data), "--out", str(out), "--demos", "3000", "--workers", "2"],
        "render-obs": ["render-obs", str(data), "--camera", "front", "--size", "48", "--workers", "2"],
        "merge": ["merge", str(data), str(data.parent / "fixture"), "--out", str(out) + ".hdf5"],
        "split": ["split", str(data), "--valid", "0.3"],
        "export-npz": ["export", str(data), "--to", "npz", "--out", str(out)],
        "export-minari": ["export", str(data), "--to", "minari", "--dataset-id", f"soak/{out.name}-v0"],
        "export-lerobot": ["export", str(data), "--to", "lerobot", "--repo-id", "soak/x", "--out", str(out),
                           "--cameras", "front", "--image-size", "48"],
        "view": ["view", str(data), "--out", str(out), "--size", "48", "--workers", "2"],
        "info": ["info", str(data)],
        "replay": ["replay", str(data), "--check"],
        "train": ["train", str(data), "--out", str(out), "--steps", "3000"],
        "eval": ["eval", str(run_dir), "--episodes", "200"],
    }


EDITS = {"render-obs", "split"}
"""Tools that edit their input in place (the rest must leave it byte for byte)."""
TORCH = {"train", "eval"}


def digest(path: pathlib.Path) -> str:
    h = hashlib.sha256()
    for p in sorted(path.rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(path)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def descendants(pid: int) -> set[int]:
    found, todo = set(), [pid]
    while todo:
        for child in children(todo.pop()):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def valid(path: pathlib.Path, python: str) -> str | None:
    """None if `gym-fetch info` calls the dataset at `path` valid, or its only problems are images a
    stopped collector had not rendered yet (its next session renders them); else what it says."""
    run = subprocess.run([python, "-m", "fetch.cli", "info", str(path)], capture_output=True, text=True, timeout=300)
    if run.returncode == 0:
        return None
    problems = [line for line in run.stdout.splitlines() if line.startswith("  - ")]
    if run.returncode == 1 and problems and all("not rendered yet" in line for line in problems):
        return None
    return (problems or run.stderr.strip().splitlines() or [f"exit {run.returncode}"])[-1].strip()


def one_round(tool: str, stop: str, rng: random.Random, fixture: pathlib.Path, run_dir: pathlib.Path,
              root: pathlib.Path, python: str, train_python: str) -> str | None:
    """Run `tool`, stop it with `stop`; None if every check passed, else what failed."""
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    data, out = root / "data", root / "out"
    tmp = root.parent / "tmp" / tool  # shared by the tool's rounds: what one leaves, the next must clean
    tmp.mkdir(parents=True, exist_ok=True)
    left_before = {p.name for p in tmp.iterdir()}
    shutil.copytree(fixture, data)
    shutil.copytree(fixture, root / "fixture")  # merge's second input
    before = digest(data)
    env = dict(os.environ, TMPDIR=str(tmp), MINARI_DATASETS_PATH=str(root / "minari"),
               HF_LEROBOT_HOME=str(root / "lerobot"))
    command = pathlib.Path(train_python if tool in TORCH else python).with_name("gym-fetch")  # as people run it
    argv = [str(command), *tool_commands(data, out, run_dir)[tool]]
    stdout: int | object = subprocess.PIPE
    full = None
    if stop == "full-stdout":
        full = open("/dev/full", "w")  # noqa: SIM115
        stdout = full
    proc = subprocess.Popen(argv, stdout=stdout, stderr=subprocess.PIPE, text=True, env=env,  # type: ignore[arg-type]
                            start_new_session=True)
    wait = rng.uniform(0.5, 6.0)
    if stop == "closed-stdout":  # `| head -n 1`: one line read, then the pipe closed
        assert proc.stdout is not None
        deadline = time.time() + wait
        proc.stdout.readline()
        time.sleep(max(0.0, deadline - time.time()))
        proc.stdout.close()
    else:
        time.sleep(wait)
    workers = descendants(proc.pid)
    if proc.poll() is None:
        if stop == "kill":
            proc.send_signal(signal.SIGKILL)
        elif stop in ("term", "closed-stdout", "full-stdout"):  # a tool that lost its stdout must still stop
            proc.send_signal(signal.SIGTERM)
        elif stop in ("group-int", "double-int"):
            os.killpg(proc.pid, signal.SIGINT)
            if stop == "double-int":
                time.sleep(rng.uniform(0.01, 0.3))
                try:
                    os.killpg(proc.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
    problems = []
    try:
        proc.wait(timeout=GRACE)
    except subprocess.TimeoutExpired:
        problems.append(f"no exit within {GRACE:.0f} s")
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    stderr = proc.stderr.read() if proc.stderr else ""
    if proc.stdout and not proc.stdout.closed:
        proc.stdout.read()
    if full is not None:
        full.close()
    code = proc.returncode
    allowed = {0, 128 + signal.SIGTERM, -signal.SIGTERM} if stop == "term" else \
        {0, -signal.SIGKILL} if stop == "kill" else {0, 128 + signal.SIGINT, -signal.SIGINT} \
        if stop.endswith("int") else {0, 1, 2, 128 + signal.SIGTERM, -signal.SIGTERM}
    if code not in allowed:
        problems.append(f"exit {code}")
    if "Traceback" in stderr:
        tail = stderr[stderr.rindex("Traceback"):].strip().splitlines()
        problems.append("traceback: " + " | ".join(line.strip() for line in tail[-7:])[:700])
    deadline = time.time() + GRACE
    while time.time() < deadline and any(alive(p) for p in workers):
        time.sleep(0.2)
    orphans = [p for p in workers if alive(p)]
    if orphans:
        problems.append(f"{len(orphans)} worker(s) left running")
        for p in orphans:
            os.kill(p, signal.SIGKILL)
    if tool in EDITS:
        why = valid(data, python)
        if why:
            problems.append(f"input invalid: {why}")
    elif digest(data) != before:
        problems.append("input changed")
    produced = pathlib.Path(str(out) + ".hdf5") if tool == "merge" else out
    if tool in ("collect", "collect-cameras", "generate", "merge") and produced.exists() and \
            (produced / "demos.hdf5" if produced.is_dir() else produced).exists():
        why = valid(produced, python)
        if why:
            problems.append(f"output invalid: {why}")
    stale = sorted(n for n in left_before & {p.name for p in tmp.iterdir()}
                   if not n.startswith("torchinductor"))  # torch's compile cache, kept on purpose
    if stale:
        problems.append(f"an earlier round's temporary files still in $TMPDIR: {stale[:3]}")
    return "; ".join(problems) or None


def prepare(base: pathlib.Path, python: str, train_python: str | None) -> tuple[pathlib.Path, pathlib.Path]:
    """The fixture dataset, and a trained run where `train_python` is given (train and eval soaked)."""
    fixture, run_dir = base / "fixture", base / "run"
    if not (fixture / "demos.hdf5").exists():
        subprocess.run([python, "-m", "fetch.cli", "collect", "--env", "PickPlace-v2", "--device", "expert",
                        "--episodes", "12", "--render", "none", "--control-hz", "0", "--out", str(fixture)],
                       check=True, capture_output=True, timeout=600)
    if train_python is not None and not (run_dir / "checkpoint.pt").exists():
        subprocess.run([train_python, "-m", "fetch.cli", "train", str(fixture), "--out", str(run_dir),
                        "--steps", "200"], check=True, capture_output=True, timeout=1200)
    return fixture, run_dir


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3, help="rounds per tool and stop (3)")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("/tmp/fetch-soak-tools"))
    parser.add_argument("--tools", default="all", help="comma-separated, or all: "
                        + ",".join(tool_commands(pathlib.Path(), pathlib.Path(), pathlib.Path())))
    parser.add_argument("--stops", default="all", help="comma-separated, or all: " + ",".join(STOPS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--train-python", default=str(pathlib.Path(__file__).resolve().parents[1]
                                                      / ".venv-train" / "bin" / "python"))
    args = parser.parse_args()
    every = list(tool_commands(pathlib.Path(), pathlib.Path(), pathlib.Path()))
    tools = every if args.tools == "all" else args.tools.split(",")
    stops = list(STOPS) if args.stops == "all" else args.stops.split(",")
    for name, chosen, valid_names in (("tool", tools, every), ("stop", stops, STOPS)):
        bad = [c for c in chosen if c not in valid_names]
        if bad:
            parser.error(f"unknown {name} {bad[0]!r}; choose from {', '.join(valid_names)}")
    python = sys.executable
    if any(t in TORCH for t in tools) and not pathlib.Path(args.train_python).exists():
        parser.error(f"train and eval need torch: --train-python {args.train_python} does not exist")
    args.out.mkdir(parents=True, exist_ok=True)
    fixture, run_dir = prepare(args.out, python, args.train_python if any(t in TORCH for t in tools) else None)
    rng = random.Random(args.seed)
    passed: dict[tuple[str, str], int] = collections.Counter()
    failures: list[str] = []
    start = time.perf_counter()
    for tool in tools:
        for stop in stops:
            for r in range(args.rounds):
                why = one_round(tool, stop, rng, fixture, run_dir, args.out / "round", python, args.train_python)
                passed[tool, stop] += why is None
                if why:
                    failures.append(f"{tool} / {stop} / round {r}: {why}")
                print(f"{tool:16s} {stop:14s} {r}: {why or 'ok'}", file=sys.stderr, flush=True)
    print(f"{len(tools) * len(stops) * args.rounds} rounds in {time.perf_counter() - start:.0f} s\n")
    print("| tool | " + " | ".join(stops) + " |")
    print("|---|" + "---|" * len(stops))
    for tool in tools:
        print(f"| {tool} | " + " | ".join(f"{passed[tool, s]}/{args.rounds}" for s in stops) + " |")
    for line in failures:
        print(f"- {line}")
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
