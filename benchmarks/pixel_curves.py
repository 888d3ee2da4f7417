"""Learning curves from the cameras against from the state: success after N of the mission's demos.

    .venv-train/bin/python -m benchmarks.pixel_curves --mission /tmp/mission [--tasks PickPlace-v2]
        [--results /tmp/gym-fetch-learning-curves] [--records FILE] [--seeds 0,1,2] [--limit K]

The demos are those `benchmarks.mission --env TASK --inputs pixels --image-size 84 --dir /tmp/mission` made
(the stand-in's 10 pad demos multiplied by `gym-fetch generate --cameras front,wrist --image-size 84`, drawn
"fast", from every start: 900 of them in mask/train, 720 where the mission made a fifth of its 1000 from tight
starts, a dataset of its own that this does not use): run that first. Each run trains, with `gym-fetch train`'s
defaults, on the first N demos of mask/train (`DEMOS`: 10, 100 and all) either the pixel policy (`--inputs pixels`)
or the state policy (`--policy auto`), with training seed 0, 1 or 2, and evaluates it on 100 episodes of seeds
disjoint from the data's. Every run's result is one line of `RECORDS` (benchmarks/out/, which git ignores; copy
it to another machine and the curves go on there: a run recorded in it is skipped), and its trained policy is
under `--results`/runs (a half-trained run resumes from its checkpoint after an interruption). After each run it
rewrites the table of docs/results/pixel_curves.md from the records (the section under `HEADING`).

A run is one `gym-fetch train` with that many demos: the pixel policy takes its 6000 steps whatever the
number of demos (on 2 cores about 9 minutes with bf16, 12 in fp32 with AVX512), the state policy the task's
steps (2-5 minutes): about 1 hour a task for each training seed's 6 runs.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import pathlib
import re
import time
from typing import Any

import numpy as np

from benchmarks._machine import cpu_model, fetch_commit, machine_line
from benchmarks.mission import mission_dir

DEMOS = (10, 100, 0)
"""Demos trained on (the first of mask/train); 0: all of them."""
INPUTS = ("pixels", "state")
SEEDS = (0, 1, 2)
EPISODES = 100
HEADING = "## Current table"
"""The section of `PAGE` this benchmark writes."""
PAGE = "results/pixel_curves.md"
"""The results page, under --docs."""
RECORDS = pathlib.Path(__file__).resolve().parent / "out" / "pixel_curves.jsonl"
"""Every run's result, one JSON object a line, oldest first: a benchmark's raw output, outside git (benchmarks/out/
is ignored). Records marked `reconstructed` were rebuilt from a published table: their success exact, their
training time their row's mean."""

IMAGE_SIZE = 84
"""[px] the images of the demos this table was made from (the mission's default before 64)."""


@dataclasses.dataclass(frozen=True)
class Job:
    task: str
    inputs: str
    demos: int
    seed: int

    @property
    def name(self) -> str:
        return f"{self.task}__{self.inputs}__n{self.demos or 'all'}__s{self.seed}"

    @classmethod
    def of(cls, record: dict[str, Any]) -> Job:
        return cls(record["task"], record["inputs"], record["demos"], record["seed"])


def jobs(tasks: list[str], seeds: tuple[int, ...]) -> list[Job]:
    """Every run, one training seed of everything first (the cheap state runs before the pixel runs)."""
    return [Job(task, inputs, demos, seed) for seed in seeds for task in tasks for inputs in reversed(INPUTS)
            for demos in DEMOS]


def generated(mission: pathlib.Path, task: str) -> pathlib.Path:
    """The mission's generated demos (with images) of `task`; a one-line error where the mission has not run."""
    path = mission_dir(mission, task, "standin", "pixels", IMAGE_SIZE) / "generated"
    if not path.exists():
        raise SystemExit(f"{path}: no generated demos with images; run `python -m benchmarks.mission --env {task} "
                         f"--inputs pixels --image-size {IMAGE_SIZE} --dir {mission}` first")
    return path


def run(job: Job, dataset: pathlib.Path, results: pathlib.Path) -> dict[str, Any]:
    """Train as `gym-fetch train DATASET [--inputs pixels] --demos N --seed S` does and evaluate."""
    from fetch.learn import load
    from fetch.learn.evaluate import evaluate
    from fetch.learn.settings import TrainRequest
    from fetch.learn.train import train

    start = time.perf_counter()
    trained = train(dataset, results / "runs" / job.name,
                    TrainRequest(inputs=job.inputs, demos=job.demos, seed=job.seed), log=lambda _: None,
                    show_progress=False)
    train_s = time.perf_counter() - start
    start = time.perf_counter()
    outcome = evaluate(load(trained.run), EPISODES)
    return {**dataclasses.asdict(job), "policy": trained.plan.policy.kind, "steps": trained.plan.config.steps,
            "train_demos": _train_demos(trained.run), "train_seconds": train_s,
            "eval_seconds": time.perf_counter() - start, "precision": trained.plan.config.precision,
            "date": time.strftime("%Y-%m-%d"), "finished": time.time(), "cpu": cpu_model(),
            "commit": fetch_commit() or "unrecorded",
            "machine": machine_line("torch"), **outcome.as_dict()}


def _cell(done: list[dict[str, Any]], demos: int) -> str:
    """"mean ± std (each seed's)" of the results `done` (in seed order): the seeds' own rates beside the mean,
    since whole-percent rounding of a spread over two or three seeds hides it (100 and 99 read "100 ± 0");
    "not run yet" where none has run."""
    if not done:
        return "not run yet"
    rates = [100 * r["success_rate"] for r in done]
    of = "" if demos else " of " + "/".join(sorted({str(r["train_demos"]) for r in done}))
    if len(rates) == 1:
        return f"{rates[0]:.0f} (seed {done[0]['seed']} only){of}"
    return f"{np.mean(rates):.0f} ± {np.std(rates):.0f} ({', '.join(f'{x:.0f}' for x in rates)}){of}"


def _place(r: dict[str, Any]) -> tuple[str, str]:
    """Where a result was measured: (CPU, precision)."""
    return r.get("cpu", "unrecorded CPU"), r.get("precision", "unrecorded precision")


def _places(found: list[dict[str, Any]]) -> list[tuple[str, str]]:
    """The places of the results `found`, in the order of the first date each was used on."""
    first = {place: min(r.get("date", "undated") for r in found if _place(r) == place)
             for place in {_place(r) for r in found}}
    return sorted(first, key=lambda place: (first[place], *place))


def where_run(found: list[dict[str, Any]]) -> str:
    """The CPUs and precisions the results were measured with, one clause each with its number of runs,
    numbered [1], [2] ... where there are several (the times in the table are only comparable within one
    clause, and say which). The commits and dates of each run are in the records, not on the page."""
    runs = collections.Counter(_place(r) for r in found)
    clauses = [f"{cpu}, {precision} ({runs[(cpu, precision)]} run{'s' * (runs[(cpu, precision)] > 1)})"
               for cpu, precision in _places(found)]
    return "; ".join(clauses if len(clauses) == 1 else (f"[{i}] {c}" for i, c in enumerate(clauses, 1)))


def versions(found: list[dict[str, Any]]) -> str:
    """python's and the libraries' versions on the machine line of the latest run that recorded one."""
    lines = [r for r in found if r.get("machine")]
    if not lines:
        return "unrecorded"
    line = max(lines, key=lambda r: r.get("finished", 0.0))["machine"]
    tail = line[line.find("python "):] if "python " in line else line
    return re.sub(r"fetch [^,]*, ", "", tail)


def _seconds(rows: list[dict[str, Any]], places: list[tuple[str, str]]) -> str:
    """The mean training time of `rows`' runs, one per place they ran ("712 [1]; 377 [3]", numbered by their
    index in `places`, all the results' places, as `where_run` numbers them): a mean over two machines would be
    neither's."""
    means = {place: np.mean([r["train_seconds"] for r in rows if _place(r) == place]) for place in places
             if any(_place(r) == place for r in rows)}
    if len(places) == 1:
        return f"{next(iter(means.values())):.0f}"
    return "; ".join(f"{seconds:.0f} [{places.index(place) + 1}]" for place, seconds in means.items())


def _train_demos(run_dir: pathlib.Path) -> int:
    from fetch.learn import checkpoint

    return len(checkpoint.read(run_dir)["source"]["train_demos"])


def load(records: pathlib.Path) -> list[dict[str, Any]]:
    """The results recorded in `records` ([] where there is no such file)."""
    if not records.exists():
        return []
    return [json.loads(line) for line in records.read_text().splitlines() if line.strip()]


def record(records: pathlib.Path, result: dict[str, Any]) -> None:
    """Add `result` to `records`, whole or not at all (written beside it, then put in its place)."""
    records.parent.mkdir(parents=True, exist_ok=True)
    before = records.read_text() if records.exists() else ""
    tmp = records.with_name(f".{records.name}.tmp")
    tmp.write_text(before + json.dumps(result, sort_keys=True) + "\n")
    tmp.replace(records)


def table(found: list[dict[str, Any]]) -> str:
    """This benchmark's section of `PAGE` from the results `found` ("" without any)."""
    if not found:
        return ""
    lines = [HEADING, "",
             "Written by `benchmarks/pixel_curves.py`. Success % over "
             f"{EPISODES} unseen evaluation seeds, mean ± std over the training seeds done (in brackets each seed's "
             "own, in seed order); \"all\" is all of mask/train (their count after \"of\"). The last column is the "
             "mean training wall time of a run on 2 cores (on each machine, numbered as below, where they differ).", "",
             "| task | sees | " + " | ".join(f"{n or 'all'} demos" for n in DEMOS)
             + " | train [s] per run |", "|---|---|" + "---|" * (len(DEMOS) + 1)]
    places = _places(found)
    for task in sorted({r["task"] for r in found}):
        for inputs in INPUTS:
            rows = [r for r in found if r["task"] == task and r["inputs"] == inputs]
            if not rows:
                continue
            cells = []
            for n in DEMOS:
                done = sorted((r for r in rows if r["demos"] == n), key=lambda r: r["seed"])
                cells.append(_cell(done, n))
            lines.append(f"| `{task}` | {inputs} ({rows[0]['policy']}) | " + " | ".join(cells)
                         + f" | {_seconds(rows, places)} |")
    lines += ["", f"Machines (2 cores each): {where_run(found)}.", "",
              f"Versions (the latest run): {versions(found)}.", "",
              f"Measured on {max(r.get('date', 'undated') for r in found)} (the latest run)."]
    return "\n".join(lines) + "\n"


def section(text: str, heading: str) -> str:
    """The part of a markdown page from the line `heading` to the next "## " heading ("" without it)."""
    lines = text.splitlines(keepends=True)
    if heading + "\n" not in lines:
        return ""
    start = lines.index(heading + "\n")
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
    return "".join(lines[start:end])


def with_section(text: str, heading: str, new: str) -> str:
    """`text` with its section under `heading` replaced by `new` (added at the end where it has none)."""
    old = section(text, heading)
    if not old:
        return text.rstrip("\n") + "\n\n" + new
    before, after = text.split(old, 1)
    return before + new + ("\n" + after if after else "")


def publish(found: list[dict[str, Any]], docs: pathlib.Path) -> None:
    page = docs / PAGE
    text = table(found)
    if not text:
        return
    tmp = page.with_name(f".{page.name}.tmp")
    tmp.write_text(with_section(page.read_text() if page.exists() else "# Pixel curves\n", HEADING, text))
    tmp.replace(page)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mission", default="/tmp/mission", help="benchmarks.mission's --dir (default %(default)s)")
    p.add_argument("--tasks", default="PickPlace-v2", help="comma-separated (default %(default)s)")
    p.add_argument("--results", default="/tmp/gym-fetch-learning-curves",
                   help="where the trained runs go: <results>/runs (default %(default)s)")
    p.add_argument("--records", default=str(RECORDS), help="the results file (default: the repo's %(default)s)")
    p.add_argument("--docs", default=str(pathlib.Path(__file__).resolve().parents[1] / "docs"),
                   help=f"the docs folder holding {PAGE} (default: the repo's docs/)")
    p.add_argument("--seeds", default=",".join(map(str, SEEDS)), help="training seeds (default %(default)s)")
    p.add_argument("--limit", type=int, default=0, help="stop after this many new runs (default 0: all)")
    args = p.parse_args(argv)
    import fetch  # noqa: F401  (registers the ids)
    from fetch.tasks import REGISTRATIONS

    known = [r.env_id for r in REGISTRATIONS]
    tasks = args.tasks.split(",")
    if unknown := [t for t in tasks if t not in known]:
        p.error(f"--tasks: unknown {', '.join(unknown)}; choose from {', '.join(known)}")
    results, docs, records = pathlib.Path(args.results), pathlib.Path(args.docs), pathlib.Path(args.records)
    print(machine_line("torch"))
    found = load(records)
    done = {Job.of(r) for r in found}
    new = 0
    for job in jobs(tasks, tuple(int(s) for s in args.seeds.split(","))):
        if job in done:
            continue
        if args.limit and new >= args.limit:
            break
        outcome = run(job, generated(pathlib.Path(args.mission), job.task), results)
        record(records, outcome)
        found.append(outcome)
        new += 1
        print(f"{job.name}: {100 * outcome['success_rate']:.0f} % (train {outcome['train_seconds']:.0f} s, "
              f"eval {outcome['eval_seconds']:.0f} s)", flush=True)
        publish(found, docs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
