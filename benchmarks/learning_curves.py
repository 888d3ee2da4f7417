"""Learning curves: how a policy trained on N expert demos does, per task, recording and policy.

Run with the train extra installed (torch; matplotlib for the plot, optional):

    nice -n 10 python -m benchmarks.learning_curves --results /tmp/learning_curves

Every run (task, recording, policy, demos, training seed) trains with `fetch.learn.train` and
evaluates 100 episodes on seeds disjoint from the data's; its result is one JSON file under
`--results`, so a killed benchmark picks up where it stopped (a run already done is skipped, a
half-trained one resumes from its checkpoint). After every run it rewrites the results page
(`docs/results/learning_curves.md`) and the plot (`docs/images/learning_curves.png`) from the results so far.

Recordings, each made once by `gym-fetch collect --device expert` with the flags in `RECORDINGS`:
`dart` is the collector's default (the executed action perturbed by N(0, 0.1), the expert's clean
action recorded as `expert_actions` and learned; DART: Laskey et al. 2017; demos run the 50-step
horizon), `stop` the plain expert ending 10 steps after success (the collector's default before),
`hold` the plain expert running the horizon, `dartstop` DART ending at success.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import platform
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from benchmarks._machine import cpu_model, version

CURVE_TASKS = ("Push-v2", "PickPlace-v2", "Drawer-open-v2", "Bin-place-v2", "Box-close-v2")
ALL_TASKS = ("Bin-pick-v2", "Bin-place-v2", "Box-open-v2", "Box-close-v2", "Drawer-open-v2", "Drawer-close-v2",
             "Reach-v2", "Push-v2", "PickPlace-v2", "Slide-v2")
CURVE_DEMOS = (10, 30, 100, 300)
SEEDS = (0, 1, 2)
EPISODES = 100
RECORDINGS: dict[str, tuple[str, ...]] = {
    "stop": ("--expert-noise", "0", "--stop-on-success"),
    "hold": ("--expert-noise", "0", "--no-stop-on-success"),
    "dart": (),
    "dartstop": ("--stop-on-success",),
    "dart2": ("--expert-noise", "0.2"),
}
"""`collect --device expert --max-steps 50` flags of each recording ("dart": the collector's defaults)."""
COMPARED = ("stop", "hold", "dart")
"""The recordings the comparison table shows."""
POLICY_VARIANTS: dict[str, dict[str, Any]] = {
    "mlp-chunk": {"kind": "mlp-chunk"},
    "mlp": {"kind": "mlp-chunk", "chunk": 1},
    "gru": {"kind": "gru"},
}
"""Policies compared: the default chunked MLP, plain BC (chunk 1), and the recurrent policy."""
MEASURED_VARIANTS: dict[str, dict[str, Any]] = {
    "mlp-chunk-x5": {"kind": "mlp-chunk", "members": 5},
    "mlp-chunk-x5-offsets": {"kind": "mlp-chunk", "members": 5, "goal_offsets": True},
    "gru-offsets": {"kind": "gru", "goal_offsets": True},
    "mlp-chunk-x5-offsets-mirror": {"kind": "mlp-chunk", "members": 5, "goal_offsets": True, "mirror": True},
    "gru-mirror": {"kind": "gru", "mirror": True},
}
"""What `--policy auto` trains where it adds settings to a kind (the task's recipe, `fetch.learn.recipes`): an
ensemble, goal offsets; `mirror` is the training setting (`Training.mirror`: the demos'
mirror images too)."""


def auto_variant(task: str) -> str:
    """The name (a `POLICY_VARIANTS` or `MEASURED_VARIANTS` key) of what `gym-fetch train --policy auto` trains
    on `task`."""
    from fetch.learn.recipes import Training, task_training

    auto, plain = task_training(task), Training()
    changed = [name for name in Training._fields
               if name not in ("policy", "steps") and getattr(auto, name) != getattr(plain, name)]
    settings = {"kind": auto.policy, **{name: getattr(auto, name) for name in changed}}
    return next((name for name, variant in MEASURED_VARIANTS.items() if variant == settings), settings["kind"])


@dataclasses.dataclass(frozen=True)
class Job:
    task: str
    recording: str
    policy: str
    demos: int
    seed: int
    steps: int | None = None
    """gradient steps where `gym-fetch train` takes other than the default (`measured_steps`);
    None: the benchmark's `--steps`."""

    @property
    def name(self) -> str:
        more = f"__{self.steps}steps" if self.steps else ""
        return f"{self.task}__{self.recording}__{self.policy}__n{self.demos}__s{self.seed}{more}"


def measured_steps() -> dict[str, int]:
    """The tasks on which `gym-fetch train` takes other than the default steps, and those steps."""
    from fetch.learn.recipes import RECIPES, Training

    return {env_id: recipe.steps for env_id, recipe in RECIPES.items() if recipe.steps != Training().steps}


def jobs() -> Iterator[Job]:
    """Every run, in the order they are worth having: one training seed of everything (the 100-demo point
    on every task, which is the bar, then the comparisons and the curves), then the next seed."""
    for seed in SEEDS:  # the bar, with the defaults: DART recording, `gym-fetch train --policy auto`, its steps
        for task in ALL_TASKS:
            yield Job(task, "dart", auto_variant(task), 100, seed, measured_steps().get(task))
    for seed in SEEDS:
        for task in ALL_TASKS:
            yield Job(task, "stop", "mlp-chunk", 100, seed)
        for recording in ("hold", "dart"):
            for task in CURVE_TASKS:
                yield Job(task, recording, "mlp-chunk", 100, seed)
        for task in ("PickPlace-v2", "Push-v2"):
            yield Job(task, "stop", "mlp", 100, seed)
        for demos in (10, 30, 300):
            for task in CURVE_TASKS:
                yield Job(task, "stop", "mlp-chunk", demos, seed)
    for task in ("PickPlace-v2", "Push-v2"):
        yield Job(task, "stop", "gru", 100, 0)


def collected(results: pathlib.Path, task: str, recording: str, demos: int) -> pathlib.Path:
    """The dataset of (task, recording) with at least `demos` demos in mask/train, collected once;
    a collection cut short is discarded and made again."""
    from fetch.dataset import open_dataset

    size = 350 if task in CURVE_TASKS and recording == "stop" else 120  # mask/valid takes 10 %: 315 to train on
    done = results / "data" / f"{task}__{recording}"
    if done.exists():
        return done
    partial = results / "data" / f".{done.name}.partial"
    shutil.rmtree(partial, ignore_errors=True)
    partial.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "fetch.cli", "collect", "--env", task, "--device", "expert", "--episodes",
           str(size), "--render", "none", "--max-steps", "50", "--out", str(partial), *RECORDINGS[recording]]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    with open_dataset(partial) as ds:
        assert len(ds.masks()["train"]) >= demos, (task, recording, len(ds.masks()["train"]))
    partial.rename(done)
    return done


def run(job: Job, results: pathlib.Path, steps: int) -> dict[str, Any]:
    dataset = collected(results, job.task, job.recording, job.demos)
    outcome = train_and_evaluate(dataset, results / "runs" / job.name, job.policy, job.seed, job.steps or steps,
                                 job.demos)
    return {**dataclasses.asdict(job), **outcome, "date": time.strftime("%Y-%m-%d"), "cpu": cpu_model(),
            "cores": os.cpu_count(), "versions": f"python {platform.python_version()}, mujoco {version('mujoco')}, "
                                                 f"torch {version('torch')}"}


def train_and_evaluate(dataset: pathlib.Path, run_dir: pathlib.Path, policy_name: str, seed: int, steps: int,
                       demos: int = 0) -> dict[str, Any]:
    """Train `policy_name` (a `POLICY_VARIANTS` key) on the first `demos` of the dataset's mask/train (0:
    all) and evaluate it on `EPISODES` seeds disjoint from the data's: the one harness every benchmark uses."""
    from fetch.learn import load
    from fetch.learn.evaluate import evaluate
    from fetch.learn.kinds import PolicySettings
    from fetch.learn.settings import TrainConfig, TrainPlan
    from fetch.learn.train import train

    policy = dict({**POLICY_VARIANTS, **MEASURED_VARIANTS}[policy_name])
    mirror = bool(policy.pop("mirror", False))
    config = TrainConfig(steps=steps, seed=seed, demos=demos, mirror=mirror)
    start, cpu = time.perf_counter(), time.process_time()
    trained = train(dataset, run_dir, TrainPlan(PolicySettings.of(**policy), config), log=lambda _: None,
                    show_progress=False)
    train_s, train_cpu = time.perf_counter() - start, time.process_time() - cpu
    start, cpu = time.perf_counter(), time.process_time()
    outcome = evaluate(load(trained.run), EPISODES)
    # CPU seconds are what a run costs on an idle machine; wall seconds here include the other work.
    return {"policy_settings": trained.plan.policy.as_dict(), "train": dataclasses.asdict(config),
            "steps": steps, "train_seconds": train_s, "train_cpu_seconds": train_cpu,
            "resumed_from": trained.resumed_from, "eval_seconds": time.perf_counter() - start,
            "eval_cpu_seconds": time.process_time() - cpu,
            "valid_loss": trained.valid_loss, "train_loss": trained.train_loss, **outcome.as_dict()}


def write_json(path: pathlib.Path, value: Any) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(value, f, indent=1)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def load_results(results: pathlib.Path) -> list[dict[str, Any]]:
    return [json.loads(p.read_text()) for p in sorted((results / "results").glob("*.json"))]


def _cell(rows: list[dict[str, Any]]) -> str:
    if not rows:
        return ""
    rates = [100 * r["success_rate"] for r in rows]
    spread = f" ± {np.std(rates):.0f}" if len(rates) > 1 else ""
    return f"{np.mean(rates):.0f}{spread} ({len(rates)})"


def report(results: list[dict[str, Any]], steps: int) -> str:
    """The markdown table of every result so far."""

    def pick(**match: Any) -> list[dict[str, Any]]:
        return [r for r in results if all(r[k] == v for k, v in match.items())]

    lines = ["# Learning curves", "",
             "How a policy trained on N expert demos does, per task, recording and policy: each run trains on "
             "`gym-fetch collect --device expert` demos and evaluates on seeds none of them used.", "",
             "```bash", "python -m benchmarks.learning_curves --results runs/curves   # resumes; "
             "--report-only rewrites this page", "```", "",
             f"Success % is `is_success` at step 50 of {EPISODES} evaluation episodes on seeds from 1,000,000 up, "
             "mean ± std over the training seeds that have finished (their count in brackets). "
             f"{steps} gradient steps per run "
             f"({'; '.join(f'{n} on {t}' for t, n in sorted(measured_steps().items()))} in the first table, as "
             "`gym-fetch train` takes there), one thread, on a 2-core x86 VM shared with other work.", ""]
    sections = (("## 100 expert demos, every task, with the defaults (the bar: >= 80 % on all but Slide)",
                 "Recorded as `gym-fetch collect --device expert` now does (DART noise 0.1, to the horizon; the "
                 "policy learns `expert_actions`), trained with `gym-fetch train`'s default policy (`auto`: gru, "
                 "but mlp-chunk on Drawer-close, and on Push an ensemble of 5 mlp-chunks with goal offsets; on Push "
                 "and PickPlace it also learns from the demos' mirror images), "
                 "whose choice is in the last table here.",
                 "dart", None),
                ("## 100 expert demos, every task, as first measured",
                 "Recorded as the collector did before (no noise, ending 10 steps after success), policy "
                 "`mlp-chunk`.", "stop", "mlp-chunk"))
    for title, what, recording, kind in sections:
        named = kind is None  # the policy differs by task: a column says which
        lines += [title, "", what, "",
                  f"| task | {'policy | ' if named else ''}success % | mean steps to success | train CPU [s] per run "
                  "| train wall [s] |", "|---|" + "---|" * (5 if named else 4)]
        for task in ALL_TASKS:
            policy = kind or auto_variant(task)
            # The bar's runs take the steps `gym-fetch train` takes on the task (a result's `steps`: those it took).
            rows = pick(task=task, recording=recording, policy=policy, demos=100,
                        **({"steps": measured_steps().get(task, steps)} if named else {}))
            length = f"{np.mean([r['mean_length'] for r in rows]):.1f}" if rows else ""
            cpu = [r["train_cpu_seconds"] for r in rows if "train_cpu_seconds" in r]
            seconds = f"{np.mean(cpu):.0f}" if cpu else ""
            wall = f"{np.mean([r['train_seconds'] for r in rows]):.0f}" if rows else ""
            which = f"{policy} | " if named else ""
            lines.append(f"| `{task}` | {which}{_cell(rows)} | {length} | {seconds} | {wall} |")
        lines.append("")
    lines += ["## Success % against the number of demos (stop-at-success recording)", "",
              "| task | " + " | ".join(str(n) for n in CURVE_DEMOS) + " |", "|---|" + "---|" * len(CURVE_DEMOS)]
    for task in CURVE_TASKS:
        cells = [_cell(pick(task=task, recording="stop", policy="mlp-chunk", demos=n)) for n in CURVE_DEMOS]
        lines.append(f"| `{task}` | " + " | ".join(cells) + " |")
    lines += ["", "![Success against the number of demos, mlp-chunk](../images/learning_curves.png)"]
    lines += ["", "## How the demos are recorded (100 demos)", "",
              "stop: the attempt ends 10 steps after success (the collector's default); hold: "
              "`--no-stop-on-success`, every demo runs the 50-step horizon; dart: as hold, the executed action "
              "perturbed by N(0, 0.1) noise and the expert's clean action as the label.", "",
              "| task | " + " | ".join(COMPARED) + " |", "|---|" + "---|" * len(COMPARED)]
    for task in CURVE_TASKS:
        cells = [_cell(pick(task=task, recording=rec, policy="mlp-chunk", demos=100)) for rec in COMPARED]
        lines.append(f"| `{task}` | " + " | ".join(cells) + " |")
    lines += ["", "## Policies (100 stop-at-success demos)", "",
              "mlp-chunk: 10-action chunks with temporal ensembling; mlp: one action (plain BC); gru: recurrent.", "",
              "| task | " + " | ".join(POLICY_VARIANTS) + " | train [s] per run |",
              "|---|" + "---|" * (len(POLICY_VARIANTS) + 1)]
    for task in ("PickPlace-v2", "Push-v2"):
        cells = [_cell(pick(task=task, recording="stop", policy=p, demos=100)) for p in POLICY_VARIANTS]
        seconds = ", ".join(f"{p} {np.mean([r['train_seconds'] for r in rows]):.0f}" for p in POLICY_VARIANTS
                            if (rows := pick(task=task, recording="stop", policy=p, demos=100)))
        lines.append(f"| `{task}` | " + " | ".join(cells) + f" | {seconds} |")
    return "\n".join(lines) + "\n"


def machines(results: list[dict[str, Any]]) -> list[str]:
    """The page's last section: the CPUs and versions the results ran with, and the latest run's date."""
    seen = sorted({f"{r['cpu']}, {r['cores']} cores; {r['versions']}" for r in results if "cpu" in r})
    dates = [r["date"] for r in results if "date" in r]
    return (["", "## Machine and versions", "", *(f"- {s}" for s in seen or ["not recorded with these runs"])]
            + ([f"\nLatest run measured on {max(dates)}."] if dates else []))


def plot(results: list[dict[str, Any]], path: pathlib.Path) -> bool:
    """Success against demos per curve task (mean and spread over seeds); False without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    for task in CURVE_TASKS:
        xs, means, stds = [], [], []
        for n in CURVE_DEMOS:
            rates = [100 * r["success_rate"] for r in results if r["task"] == task and r["recording"] == "stop"
                     and r["policy"] == "mlp-chunk" and r["demos"] == n]
            if rates:
                xs.append(n)
                means.append(float(np.mean(rates)))
                stds.append(float(np.std(rates)))
        if xs:
            ax.errorbar(xs, means, yerr=stds, marker="o", capsize=3, label=task)
    ax.set_xscale("log")
    ax.set_xticks(CURVE_DEMOS, [str(n) for n in CURVE_DEMOS])
    ax.set_ylim(-2, 102)
    ax.set_xlabel("expert demos (stop at success)")
    ax.set_ylabel(f"success % ({EPISODES} episodes, mean of seeds)")
    ax.axhline(80, color="grey", lw=0.8, ls=":")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.tmp.png")
    fig.savefig(tmp)
    plt.close(fig)
    os.replace(tmp, path)
    return True


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", default="/tmp/gym-fetch-learning-curves",
                   help="directory of datasets, runs and one result file per run (default %(default)s)")
    p.add_argument("--docs", default=str(pathlib.Path(__file__).resolve().parents[1] / "docs"),
                   help="the docs folder: results/learning_curves.md and images/learning_curves.png go there "
                        "(default: the repo's docs/)")
    p.add_argument("--steps", type=int, default=None, help="gradient steps per run (default: gym-fetch train's)")
    p.add_argument("--limit", type=int, default=0, help="stop after this many new runs (default 0: all)")
    p.add_argument("--shard", default="0/1", metavar="K/N",
                   help="run only the tasks of shard K of N (each task's data stays in one shard): one "
                        "process per core, e.g. 0/2 and 1/2 (default %(default)s: everything)")
    p.add_argument("--tasks", default=",".join(ALL_TASKS),
                   help="run only these tasks' jobs (comma-separated; default: all)")
    p.add_argument("--report-only", action="store_true", help="rewrite the table and plot from the results; no runs")
    args = p.parse_args(argv)
    import fetch  # noqa: F401  (registers the ids)
    from fetch.learn.settings import TrainConfig

    steps = args.steps or TrainConfig().steps
    results = pathlib.Path(args.results)
    (results / "results").mkdir(parents=True, exist_ok=True)
    docs = pathlib.Path(args.docs)
    (docs / "images").mkdir(parents=True, exist_ok=True)
    shard, shards = (int(x) for x in args.shard.split("/"))
    tasks = args.tasks.split(",")
    if unknown := sorted(set(tasks) - set(ALL_TASKS)):
        p.error(f"--tasks: unknown {', '.join(unknown)}; choose from {', '.join(ALL_TASKS)}")
    new = 0
    for job in ([] if args.report_only else list(jobs())):
        if ALL_TASKS.index(job.task) % shards != shard or job.task not in tasks:
            continue
        target = results / "results" / f"{job.name}.json"
        if target.exists():
            continue
        if args.limit and new >= args.limit:
            break
        outcome = run(job, results, steps)
        write_json(target, outcome)
        new += 1
        print(f"{job.name}: {100 * outcome['success_rate']:.0f}% (train {outcome['train_seconds']:.0f} s, "
              f"eval {outcome['eval_seconds']:.0f} s)", flush=True)
        _publish(results, docs, steps)
    _publish(results, docs, steps)
    return 0


def choices_table(results: pathlib.Path) -> str:
    """The table of `experiments/train_choices.py`'s runs (one seed each), if it has run."""
    runs = [json.loads(p.read_text()) for p in sorted((results / "choices").glob("*.json"))]
    runs = [r for r in runs if r.get("seed", 0) == 0]  # other training seeds: train_choices.py --seed
    if not runs:
        return ""
    variants = sorted({r["variant"] for r in runs}, key=lambda v: (v != "dart-5k", v))
    tasks = [t for t in ALL_TASKS if any(r["task"] == t for r in runs)]
    rate = {(r["task"], r["variant"]): f"{100 * r['success_rate']:.0f}" for r in runs}
    cpu = {v: np.mean([r["train_cpu_seconds"] for r in runs if r["variant"] == v]) for v in variants}
    lines = ["## Choosing the defaults (`experiments/train_choices.py`, 100 DART demos, one training seed)", "",
             "Each variant changes one thing from `dart-5k` (mlp-chunk, 5000 steps): `dartstop` demos end 10 steps "
             "after success; `c20` 20-action chunks; `512x3` a wider, deeper MLP; `on05` observation noise 0.05; "
             "`gru` the recurrent policy (128 units, windows of 10 steps); `gru50` with windows of the whole 50-step "
             "demo (batches of 64); `10k`/`30k` longer training; `x5` an ensemble of 5 (`--members 5`). "
             "Success % over 100 episodes; the last row is the mean training CPU time.", "",
             "| task | " + " | ".join(variants) + " |", "|---|" + "---|" * len(variants)]
    for task in tasks:
        lines.append(f"| `{task}` | " + " | ".join(rate.get((task, v), "") for v in variants) + " |")
    lines.append("| train CPU [s] | " + " | ".join(f"{cpu[v]:.0f}" for v in variants) + " |")
    return "\n".join(lines) + "\n"


def _publish(results: pathlib.Path, docs: pathlib.Path, steps: int) -> None:
    found = load_results(results)
    text = report(found, steps)
    choices = choices_table(results)
    if choices:
        text += "\n" + choices
    text += "\n".join(machines(found)) + "\n"
    (docs / "results").mkdir(parents=True, exist_ok=True)
    tmp = docs / "results" / ".learning_curves.md.tmp"
    tmp.write_text(text)
    os.replace(tmp, docs / "results" / "learning_curves.md")
    if not plot(found, docs / "images" / "learning_curves.png"):
        print("matplotlib is not installed: no plot (pip install matplotlib)", file=sys.stderr)


if __name__ == "__main__":
    raise SystemExit(main())
