"""Where a mission's time goes: each stage's wall time split by what its processes were doing.

    python -m benchmarks.mission_profile [--env Bin-place-v2] [--inputs pixels|state] [--isa native|avx2]
        [--image-size 64] [--source DEMOS] [--generated 40] [--steps 100] [--episodes 20] [--dir /tmp/mission_profile]

The stages of `benchmarks.mission` (`gym-fetch generate`, `train`, `eval`), run as the mission runs them
but smaller, each under py-spy (`pip install py-spy`), which samples every process's Python stack 50 times a
second, waiting or not, with no change to the program. Each sample of a process's main thread is put in
the first of its stage's categories (`CATEGORIES`) that one of its frames names; a stage's time is split
in those shares. `generate`'s are its worker processes' (the parent writes the dataset and otherwise
waits for them). The per-unit figures (seconds a demo, a step, an episode) scale to the mission's size:
1000 demos, the policy's default steps, 100 episodes, beside the mission's measured stage times on the
results page.

`--isa avx2` holds torch to AVX2 (`ATEN_CPU_CAPABILITY=avx2`, oneDNN's `ONEDNN_MAX_CPU_ISA=AVX2`) and
trains in fp32, as on a laptop CPU without AVX512: the profile of such a machine on one that has more
(rendering is llvmpipe's, which this does not hold back). `--source`: the pad demos to generate from (a
mission's `human` folder); else 10 demos by the scripted expert. Each stage's output stays in `--dir`;
a stage is run again only when its output is missing.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import time

from benchmarks._machine import machine_line
from fetch.camera_obs import DEFAULT_IMAGE_SIZE

RATE = 50
"""[Hz] py-spy's samples a second."""

CATEGORIES: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = {
    "generate": (
        ("start-up: imports, the env", ("_find_and_load (", "_init_worker (")),
        ("rendering the images (EGL)", ("Generator.render (", "StateRenderer.")),
        ("physics (mj_step)", ("Robot.advance (", "settle_room (", "settle_classic (")),
        ("reading the source demos", ("h5py/", "fetch/dataset/")),
        ("waiting for work", ("_process_worker (concurrent/futures/process.py", "Queue.get (")),
        ("planning, the expert, the rest (Python)", ()),
    ),
    "train": (
        ("start-up: imports", ("_find_and_load (",)),
        ("loading the demos (HDF5)", ("load_demos (",)),
        ("making the examples", ("samples (fetch", "Samples.tensors (", "Normalizer.fit (")),
        ("batches: indexing, random shift", ("Batch.take (", "random_shift (", "batch_indices (")),
        ("backward", ("Tensor.backward (",)),
        ("optimizer (AdamW)", ("torch/optim/",)),
        ("validation loss, checkpoint", ("validation_loss (", "loop.<locals>.save (")),
        ("forward and loss", ("loop (fetch/learn/train.py",)),
        ("planning, the rest", ()),
    ),
    "eval": (
        ("start-up: imports, the envs", ("_find_and_load (", "make_vector_env (")),
        ("rendering the cameras (EGL)", ("CameraImages.", "OffscreenRenderer.")),
        ("the policy (torch)", ("fetch/learn/policies.py", "fetch/learn/pixels.py", "fetch/learn/runtime.py",
                                "torch/")),
        ("physics (mj_step)", ("Worlds.step (", "Robot.advance (", "settle_room (", "settle_classic (")),
        ("observations, the rest (Python)", ()),
    ),
}
"""Per stage, its categories in the order a sample is tried against them: a name and the texts of which
one frame must hold one (empty: every sample left)."""

AVX2 = {"ATEN_CPU_CAPABILITY": "avx2", "ONEDNN_MAX_CPU_ISA": "AVX2"}


def classify(raw: pathlib.Path, stage: str, workers: bool) -> collections.Counter[str]:
    """Samples per category of a py-spy raw profile (`--threads`: one line per stack, its count last), main
    threads only; of the worker processes (a stack under two processes) where `workers`, else of the first.
    """
    counts: collections.Counter[str] = collections.Counter()
    for line in raw.read_text().splitlines():
        stack, _, number = line.rpartition(" ")
        frames = re.sub(r'"[^"]*"', "", stack).split(";")  # a process's command line may hold a ";"
        processes = sum(f.startswith("process ") for f in frames)
        thread = frames[processes] if processes < len(frames) else ""
        if not thread.endswith("MainThread") or (processes > 1) != workers or "resource_tracker.py" in stack:
            continue  # (multiprocessing's resource tracker: a process that waits out the run)
        for name, marks in CATEGORIES[stage]:
            if not marks or any(mark in frame for frame in frames for mark in marks):
                counts[name] += int(number)
                break
    return counts


def profiled(argv: list[str], raw: pathlib.Path, env: dict[str, str]) -> float:
    """[s] run `argv` under py-spy (every process, idle samples too), its samples into `raw`."""
    spy = shutil.which("py-spy", path=str(pathlib.Path(sys.executable).parent)) or shutil.which("py-spy")
    if spy is None:
        raise SystemExit("py-spy is not installed here: pip install py-spy")
    start = time.perf_counter()
    subprocess.run([spy, "record", "--idle", "--threads", "--subprocesses", "--nonblocking", "-r", str(RATE),
                    "-f", "raw", "-o", str(raw), "--", *argv], env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def default_steps(env_id: str, inputs: str) -> int:
    """The gradient steps `gym-fetch train` takes by default for these inputs on `env_id`."""
    from fetch.learn.kinds import pixel_kind
    from fetch.learn.recipes import task_training

    if inputs == "pixels":
        return int(pixel_kind().training["steps"])
    return task_training(env_id).steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Bin-place-v2")
    parser.add_argument("--inputs", default="pixels", choices=("state", "pixels"))
    parser.add_argument("--isa", default="native", choices=("native", "avx2"))
    parser.add_argument("--image-size", type=int, default=DEFAULT_IMAGE_SIZE,
                        help=f"--inputs pixels: the images' side [px] (default {DEFAULT_IMAGE_SIZE}, generate's)")
    parser.add_argument("--source", help="pad demos to generate from (default: 10 scripted expert demos)")
    parser.add_argument("--generated", type=int, default=40)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--dir", default="/tmp/mission_profile")
    args = parser.parse_args()
    seeing = f"pixels{args.image_size}" if args.inputs == "pixels" else args.inputs
    root = pathlib.Path(args.dir) / f"{args.env}-{seeing}-{args.isa}"
    root.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, **(AVX2 if args.isa == "avx2" else {})}
    cli = [sys.executable, "-m", "fetch.cli"]
    source = pathlib.Path(args.source) if args.source else root / "expert"
    if not args.source and not source.exists():
        subprocess.run([*cli, "collect", "--env", args.env, "--device", "expert", "--episodes", "10", "--render",
                        "none", "--out", str(source)], check=True, env=env, stdout=subprocess.DEVNULL)
    cameras = ["--cameras", "front,wrist", "--image-size", str(args.image_size), "--image-quality", "fast"] \
        if args.inputs == "pixels" else []
    precision = ["--precision", "fp32"] if args.isa == "avx2" and args.inputs == "pixels" else []
    inputs = ["--inputs", "pixels"] if args.inputs == "pixels" else []
    stages = {
        "generate": [*cli, "generate", "--source", str(source), "--out", str(root / "generated"), "--demos",
                     str(args.generated), "--workers", str(args.workers), *cameras],
        "train": [*cli, "train", str(root / "generated"), "--out", str(root / "run"), "--steps", str(args.steps),
                  *inputs, *precision],
        "eval": [*cli, "eval", str(root / "run"), "--episodes", str(args.episodes)],
    }
    timing_file = root / "timing.json"
    timing = json.loads(timing_file.read_text()) if timing_file.exists() else {}
    for stage, argv in stages.items():
        if stage not in timing:
            timing[stage] = profiled(argv, root / f"{stage}.txt", env)
            timing_file.write_text(json.dumps(timing))
    mission_steps = default_steps(args.env, args.inputs)
    print(machine_line("torch"))
    held = ", torch held to AVX2 (fp32)" if args.isa == "avx2" else ""
    size = f" at {args.image_size} px" if args.inputs == "pixels" else ""
    print(f"{args.env} from the {args.inputs}{size}{held}: generate {args.generated} demos from "
          f"{'--source ' + str(source) if args.source else '10 expert demos'} ({args.workers} workers), train "
          f"{args.steps} steps, eval {args.episodes} episodes; py-spy at {RATE} Hz\n")
    print("| stage | wall [s] | a unit [s] | at the mission's size [min] | where the time goes |")
    print("|---|---|---|---|---|")
    for stage in stages:
        counts = classify(root / f"{stage}.txt", stage, workers=stage == "generate")
        total = sum(counts.values()) or 1
        seconds = {name: timing[stage] * n / total for name, n in counts.items()}
        split = "; ".join(f"{name} {100 * n / total:.0f} %" for name, n in counts.most_common() if n / total >= 0.01)
        startup = sum(s for name, s in seconds.items() if name.startswith("start-up"))
        if stage == "train":  # per demo: loading, examples; per 1000 steps: a checkpoint; the rest per step
            per_demo = (seconds.get("loading the demos (HDF5)", 0.0) + seconds.get("making the examples", 0.0))
            checkpoint = seconds.get("validation loss, checkpoint", 0.0)
            per_step = (timing[stage] - startup - per_demo - checkpoint) / args.steps
            mission = (startup + per_demo * 1000 / args.generated + checkpoint * max(1, mission_steps // 1000)
                       + per_step * mission_steps)
            unit = f"{per_step:.3f} a step"
            size = f"{mission_steps} steps, 1000 demos"
        else:
            done, count, what = (args.generated, 1000, "demo") if stage == "generate" else (args.episodes, 100,
                                                                                             "episode")
            per_unit = (timing[stage] - startup) / done
            mission, unit, size = startup + per_unit * count, f"{per_unit:.3f} a {what}", f"{count} {what}s"
        print(f"| {stage} | {timing[stage]:.0f} | {unit} | {mission / 60:.1f} ({size}) | {split} |")


if __name__ == "__main__":
    main()
