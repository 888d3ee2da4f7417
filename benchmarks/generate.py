"""Demo generation, measured: success rate per task, successful demos per minute, 1 vs 2 workers.

For each task, 10 source demos are recorded by the scripted expert and, separately, by an imperfect
operator (the expert with Gaussian action noise, standing in for a person); from each set, 1000
demos are generated with 2 workers. Then, on a few tasks, the same generation with 1 and with 2
workers gives the scaling efficiency (demos/min with 2) / (2 x demos/min with 1). With `--train` (run it
with the train extra installed), a policy is then trained per task on the 1000 generated demos and on the
10 sources alone, with learning_curves.py's harness, and set beside learning_curves.py's 100-expert-demo
result (`--curves`).

Resumable: every result is appended to `<out>/results.jsonl` as it is measured and skipped when the
benchmark runs again (a generation stopped midway resumes where it was). Prints a table.

    nice -n 10 python -m benchmarks.generate --out /tmp/bench-generate
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import time
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

import fetch
from fetch.experts import make_expert
from fetch.generate import GenerateConfig, generate
from fetch.teleop.devices import Command
from fetch.teleop.session import CollectConfig, Session

SCALING_TASKS = ("PickPlace-v2", "Bin-pick-v2", "Drawer-open-v2")


class NoisyExpert:
    """The expert with Gaussian noise (std `noise`) on every action: an imperfect operator."""

    name = "noisy-expert"

    def __init__(self, env: Any, noise: float, seed: int = 0) -> None:
        self.expert = make_expert(env)
        self.noise = noise
        self.rng = np.random.default_rng(seed)

    def reset(self) -> None:
        self.expert.reset()

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        action = self.expert(obs) + self.rng.normal(0.0, self.noise, 4)
        return Command(np.clip(action, -1.0, 1.0).astype(np.float32))

    def close(self) -> None:
        pass


def record_sources(env_id: str, out: pathlib.Path, count: int, noise: float) -> None:
    """`count` successful demos (resumes a partial directory)."""
    # Each source attempt ends at success (within 500 steps), as these figures were measured: not the expert's
    # collect default of the whole horizon.
    config = CollectConfig(env_id=env_id, out=str(out), episodes=count, device="expert", render="none",
                           stop_on_success=True, max_steps=500)
    if (out / "demos.hdf5").exists():
        from fetch.dataset import open_dataset

        with open_dataset(out) as ds:
            have = len(ds.demo_names)
        if have >= count:
            return
        config = dataclasses.replace(config, episodes=count - have)
    env = gym.make(env_id, max_episode_steps=config.max_steps)
    device = NoisyExpert(env, noise) if noise else make_expert_device(env)
    summary = Session(config, device, env=env, log=lambda text: None).run()
    if summary.error:
        raise SystemExit(f"recording sources for {env_id} failed: {summary.error}")


def make_expert_device(env: Any) -> Any:
    from fetch.teleop.expert import ExpertDevice

    return ExpertDevice(env)


def load_results(path: pathlib.Path) -> dict[str, dict[str, Any]]:
    if not path.exists():
        return {}
    return {row["key"]: row for row in map(json.loads, path.read_text().splitlines()) if row}


def measure(key: str, results: dict[str, dict[str, Any]], path: pathlib.Path, source: pathlib.Path,
            out: pathlib.Path, demos: int, workers: int) -> dict[str, Any]:
    if key in results:
        return results[key]
    cpu = _cpu_seconds()
    # Slide's low rate would take ~50 attempts per demo: stop at 3 per demo asked for (the rate is still measured).
    summary = generate(GenerateConfig(source=str(source), out=str(out), demos=demos, seed=10_000, workers=workers,
                                      max_attempts=3 * demos), log=lambda text: print(f"  {text}", flush=True))
    from fetch.dataset import open_dataset

    with open_dataset(out) as ds:
        attempts = int(ds.data_attrs["attempts"])
        total = len(ds.demo_names)
    row = {"key": key, "demos": total, "attempts": attempts, "success": total / attempts,
           "per_min": 60 * summary.saved / summary.seconds if summary.seconds else 0.0,
           # after the first result: without starting the workers and building their envs (~5 s)
           "steady_per_min": 60 * (summary.saved - 1) / (summary.seconds - summary.startup)
           if summary.saved > 1 and summary.seconds > summary.startup else 0.0, "startup": summary.startup,
           # CPU seconds per demo of the driver and its (joined) workers: on a machine others share, the
           # wall-clock scaling says more about their load than about ours; this does not.
           "cpu_per_demo": (_cpu_seconds() - cpu) / summary.saved if summary.saved else 0.0,
           "run_demos": summary.saved, "seconds": summary.seconds, "workers": summary.workers,
           "load": os.getloadavg()[0], "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    keep(row, results, path)
    print(f"  {key}: {row['success']:.1%} success, {row['per_min']:.0f} demos/min, load {row['load']:.1f}",
          flush=True)
    return row


def keep(row: dict[str, Any], results: dict[str, dict[str, Any]], path: pathlib.Path) -> None:
    """Append a measured row to results.jsonl (what a resumed run skips) and to `results`."""
    with path.open("a") as f:
        f.write(json.dumps(row) + "\n")
    results[row["key"]] = row


def _cpu_seconds() -> float:
    import resource

    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="/tmp/gym-fetch-bench-generate")
    p.add_argument("--tasks", default=",".join(fetch.ENV_IDS))
    p.add_argument("--sources", type=int, default=10)
    p.add_argument("--demos", type=int, default=1000)
    p.add_argument("--noise", type=float, default=0.1, help="the imperfect operator's action noise std")
    p.add_argument("--operators", default="expert,noisy")
    p.add_argument("--noisy-demos", type=int, default=None, help="demos per task from the noisy sources "
                   "(default: --demos)")
    p.add_argument("--scaling-demos", type=int, default=300)
    p.add_argument("--train", action="store_true",
                   help="then train and evaluate a policy (`gym-fetch train`'s default, learning_curves.py's harness) "
                        "on each task's generated demos and on its 10 sources alone (needs the train extra)")
    p.add_argument("--curves", default="/tmp/gym-fetch-learning-curves",
                   help="learning_curves.py's results, for the 100-expert-demo column (default %(default)s)")
    p.add_argument("--shard", default="0/1", metavar="K/N", help="run only the tasks of shard K of N (their "
                   "sources, generation and, with --train, policies), e.g. 0/2 and 1/2 in two processes (default "
                   "%(default)s)")
    args = p.parse_args()
    root = pathlib.Path(args.out)
    root.mkdir(parents=True, exist_ok=True)
    path = root / "results.jsonl"
    results = load_results(path)
    tasks = args.tasks.split(",")
    operators = args.operators.split(",")
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()}", flush=True)
    shard, shards = (int(x) for x in args.shard.split("/"))
    if shards > 1:
        tasks = [t for i, t in enumerate(tasks) if i % shards == shard]
    for operator in operators:
        for env_id in tasks:
            source = root / f"src-{operator}-{env_id}"
            record_sources(env_id, source, args.sources, args.noise if operator == "noisy" else 0.0)
            print(f"{env_id} from {operator} sources", flush=True)
            demos = args.noisy_demos or args.demos if operator == "noisy" else args.demos
            measure(f"{operator}/{env_id}/2", results, path, source, root / f"gen-{operator}-{env_id}", demos, 2)
        if operator == "expert":
            for env_id in [t for t in SCALING_TASKS if t in tasks]:
                source = root / f"src-expert-{env_id}"
                for workers in (1, 2):
                    print(f"{env_id} scaling, {workers} worker(s)", flush=True)
                    measure(f"scaling/{env_id}/{workers}", results, path, source,
                            root / f"scale{workers}-{env_id}", args.scaling_demos, workers)
    if args.train:
        for env_id in tasks:
            for kind in TRAINED:
                trained(env_id, kind, root, results, path)
    print_table(results, tasks, operators)
    print_policies(results, tasks, pathlib.Path(args.curves))


TRAINED = ("generated", "sources")
"""What a policy is trained on per task: the 1000 demos generated from the expert's 10, or those 10 alone."""


def trained(env_id: str, kind: str, root: pathlib.Path, results: dict[str, dict[str, Any]],
            path: pathlib.Path) -> dict[str, Any]:
    """Train `gym-fetch train`'s default policy for the task, with its steps, on `kind` and evaluate it (one
    training seed)."""
    from learning_curves import auto_variant, train_and_evaluate  # the harness of the 100-expert-demo figures

    from fetch.learn.recipes import task_training

    policy = auto_variant(env_id)
    steps = task_training(env_id).steps
    key = policy_key(kind, env_id)
    if key in results:
        return results[key]
    dataset = root / (f"gen-expert-{env_id}" if kind == "generated" else f"src-expert-{env_id}")
    outcome = train_and_evaluate(dataset, root / "runs" / f"{kind}-{env_id}-{policy}", policy, 0, steps)
    row = {"key": key, "task": env_id, "trained_on": kind, "policy": policy, **outcome,
           "load": os.getloadavg()[0], "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    keep(row, results, path)
    print(f"  {key}: {100 * row['success_rate']:.0f}% ({policy}, train {row['train_seconds']:.0f} s)", flush=True)
    return row


def policy_key(kind: str, env_id: str) -> str:
    """A trained policy's key in the results: what it was trained on, the policy and, where `gym-fetch train`
    takes other than its default steps on the task, those (results from before that setting lack them)."""
    from learning_curves import auto_variant

    from fetch.learn.recipes import Training, task_training

    steps = task_training(env_id).steps
    return f"policy/{kind}/{env_id}/{auto_variant(env_id)}" + (f"/{steps}steps" if steps != Training().steps else "")


def print_policies(results: dict[str, dict[str, Any]], tasks: list[str], curves: pathlib.Path) -> None:
    """Policy success trained on generated demos, on their sources, and (from learning_curves.py) on 100 expert
    demos; the bar is generated >= expert-100."""
    from learning_curves import auto_variant
    from learning_curves import load_results as curve_results

    from fetch.learn.recipes import task_training

    if not any(policy_key(kind, t) in results for kind in TRAINED for t in tasks):
        return

    curve_rows = curve_results(curves) if (curves / "results").is_dir() else []
    print("\n| task | policy | 1000 generated | 10 sources | 100 expert (DART, learning_curves.py) | "
          "generated >= expert-100 |")
    print("|---|---|---|---|---|---|")
    for env_id in tasks:
        policy = auto_variant(env_id)
        cells = [f"{100 * row['success_rate']:.0f}" if (row := results.get(policy_key(kind, env_id)))
                 else "-" for kind in TRAINED]
        expert = [r["success_rate"] for r in curve_rows
                  if (r["task"], r["recording"], r["policy"], r["demos"], r["steps"])
                  == (env_id, "dart", policy, 100, task_training(env_id).steps)]
        reference, verdict = "-", ""
        if expert:
            mean = float(np.mean(expert))
            reference = f"{100 * mean:.0f} ({len(expert)} seeds)"
            if row := results.get(policy_key("generated", env_id)):
                verdict = "yes" if row["success_rate"] >= mean else "no"
        print(f"| `{env_id}` | {policy} | {cells[0]} | {cells[1]} | {reference} | {verdict} |")


def print_table(results: dict[str, dict[str, Any]], tasks: list[str], operators: list[str]) -> None:
    print("\n| task | " + " | ".join(f"{o}: success | {o}: demos/min (2 workers)" for o in operators) + " |")
    print("|---|" + "---|---|" * len(operators))
    for env_id in tasks:
        cells = []
        for o in operators:
            row = results.get(f"{o}/{env_id}/2")
            cells += [f"{row['success']:.1%} ({row['demos']}/{row['attempts']})", f"{row['per_min']:.0f}"] if row \
                else ["-", "-"]
        print(f"| `{env_id}` | " + " | ".join(cells) + " |")
    print("\n| task | demos/min, 1 worker | 2 workers | scaling efficiency | after start-up: 1 / 2 / efficiency "
          "| CPU ms per demo: 1 / 2 / efficiency | load (1-min) |")
    print("|---|---|---|---|---|---|---|")
    for env_id in SCALING_TASKS:
        one, two = results.get(f"scaling/{env_id}/1"), results.get(f"scaling/{env_id}/2")
        if one and two:
            steady = ""
            if one.get("steady_per_min") and two.get("steady_per_min"):
                steady = (f"{one['steady_per_min']:.0f} / {two['steady_per_min']:.0f} / "
                          f"{two['steady_per_min'] / (2 * one['steady_per_min']):.2f}")
            cpu = ""
            if one.get("cpu_per_demo") and two.get("cpu_per_demo"):
                cpu = (f"{1000 * one['cpu_per_demo']:.0f} / {1000 * two['cpu_per_demo']:.0f} / "
                       f"{one['cpu_per_demo'] / two['cpu_per_demo']:.2f}")
            print(f"| `{env_id}` | {one['per_min']:.0f} | {two['per_min']:.0f} | "
                  f"{two['per_min'] / (2 * one['per_min']):.2f} | {steady} | {cpu} | "
                  f"{one['load']:.1f} / {two['load']:.1f} |")


if __name__ == "__main__":
    main()
