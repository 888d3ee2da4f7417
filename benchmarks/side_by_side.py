"""Ours beside LeRobot's ACT and Diffusion Policy: the same demos, the same seeds, the same two cores.

    .venv-lerobot06/bin/python -m benchmarks.side_by_side [--envs Bin-pick-v2,PickPlace-v2,Drawer-open-v2]
        [--inputs state,pixels] [--style person] [--seed 100] [--policies act,diffusion] [--budgets 1,4]
        [--episodes 100] [--image-size 64] [--image-quality fast] [--dir /tmp/side_by_side]
        [--mission-args "--generated 200"]

Run it with the Python of a LeRobot 0.6 venv that also holds gym-fetch-v2 and the plugin
(`pip install -e ".[lerobot]" -e plugins/lerobot_env_fetch`, docs/lerobot_env.md): every stage runs in that
one venv, so the trainers share its torch. For each task and input:

1. `benchmarks.mission` (the person stand-in's ten pad demos, `generate` to 1000, `gym-fetch train` with its
   defaults, `gym-fetch eval` on 100 unseen seeds): its training wall time is the budget;
2. the same 1000 generated demos (`gym-fetch merge`, then `gym-fetch export --to lerobot`, the cameras, image
   size and image quality the camera policy learnt from);
3. per LeRobot policy: a short probe of its training step's time, then `lerobot-train` for as many steps as
   fit in 1x and 4x the budget (`--budgets`), each a run of its own (Diffusion Policy's learning rate follows
   its schedule over the run's steps);
4. every policy, ours included (`lerobot_env_fetch.export_policy`), evaluated by `lerobot-eval` on the seeds
   `gym-fetch eval` used, in the env ours was evaluated in (its episode length, cameras, image size);
   ours' per-episode successes must equal `gym-fetch eval`'s "succeeded at some step";
5. acting rate: the actions per second a policy's own `select_action` hands out inside `lerobot-eval`, one env
   (`benchmarks.lerobot_acting`), measured after the cell's training.

LeRobot's settings are its defaults, scaled to these data (`LEROBOT_POLICIES`): the action windows cut to a
16-step prediction of which 8 are acted on (its defaults, 100 and 64 steps, are longer than the 50-step
episodes), Diffusion Policy's U-Net at the widths its authors used for low-dimensional tasks and its batch
at 64, no ImageNet weights (none can be fetched here). Each stage writes its record under `--dir` and is
skipped when it is there: an interrupted run goes on where it stopped. Prints one table.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import shlex
import shutil
import subprocess
import sys
import time
from typing import Any

from benchmarks._machine import machine_line
from benchmarks.mission import mission_dir, training_data
from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.learn import checkpoint
from fetch.rendering import DEFAULT_IMAGE_QUALITY, IMAGE_QUALITIES

LEROBOT_POLICIES: dict[str, tuple[str, ...]] = {
    "act": ("--policy.type=act", "--policy.chunk_size=16", "--policy.n_action_steps=8", "--batch_size=8"),
    "diffusion": ("--policy.type=diffusion", "--policy.horizon=16", "--policy.n_action_steps=8",
                  "--policy.down_dims=[256,512,1024]", "--batch_size=64"),
}
"""Each LeRobot policy's `lerobot-train` settings beyond its defaults."""

COMMON = ("--policy.device=cpu", "--policy.push_to_hub=false", "--policy.pretrained_backbone_weights=null",
          "--wandb.enable=false", "--num_workers=2")
"""What every `lerobot-train` here is given: the CPU, nothing uploaded or downloaded, two loader workers."""

PROBE_STEPS, PROBE_LOG = 60, 20
"""The probe's steps, and LeRobot's logging window: the last window's time per step is the one used."""


def tool(name: str) -> str:
    """A console script of the venv this Python belongs to."""
    return str(pathlib.Path(sys.executable).parent / name)


def call(argv: list[str], log: pathlib.Path) -> float:
    """[s] run `argv`, its output appended to `log`; stop the benchmark with the log's tail on failure. Offline,
    with LeRobot's home beside the log."""
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_LEROBOT_HOME": str(log.parent / "hf"), "WANDB_MODE": "disabled"}
    start = time.perf_counter()
    with log.open("a") as out:
        out.write(f"$ {' '.join(argv)}\n")
        out.flush()
        done = subprocess.run(argv, env=env, stdout=out, stderr=subprocess.STDOUT)
    if done.returncode:
        raise SystemExit(f"{argv[0]} failed ({done.returncode}); the end of {log}:\n{log.read_text()[-3000:]}")
    return time.perf_counter() - start


class Records:
    """A cell's finished stages, kept in one JSON file written after each."""

    def __init__(self, path: pathlib.Path) -> None:
        self.path = path
        self.data: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}

    def get(self, key: str, make: Any) -> Any:
        if key not in self.data:
            self.data[key] = make()
            self.path.write_text(json.dumps(self.data, indent=1))
        return self.data[key]


def seconds_per_step(log: str) -> float:
    """[s] a training step's time in lerobot-train's last logged window (update + data)."""
    windows = re.findall(r"updt_s:([0-9.]+) data_s:([0-9.]+)", log)
    if not windows:
        raise SystemExit("lerobot-train logged no step times (its log format changed?)")
    update, data = windows[-1]
    return float(update) + float(data)


def lerobot_eval(policy: pathlib.Path, env_flags: list[str], out: pathlib.Path, episodes: int, log: pathlib.Path,
                 extra: tuple[str, ...] = ("--eval.batch_size=10", "--eval.use_async_envs=false")) -> dict[str, Any]:
    """lerobot-eval of `policy` in the env `env_flags` make: its overall figures, its per-episode successes and
    its wall time."""
    shutil.rmtree(out, ignore_errors=True)
    wall = call([tool("lerobot-eval"), f"--policy.path={policy}", *env_flags, f"--eval.n_episodes={episodes}",
                 *extra, "--policy.device=cpu", f"--output_dir={out}"], log)
    info = json.loads((out / "eval_info.json").read_text())
    successes = [bool(s) for task in info["per_task"] for s in task["metrics"]["successes"]]
    return {"pc_success": info["overall"]["pc_success"], "successes": successes, "eval_s": wall}


def acting_rate(policy: pathlib.Path, env_flags: list[str], out: pathlib.Path, log: pathlib.Path) -> float:
    """[actions/s] the policy's own `select_action` (`benchmarks.lerobot_acting`) inside lerobot-eval, one env,
    five whole episodes (no end at success)."""
    flags = [f for f in env_flags if not f.startswith("--seed=")]
    shutil.rmtree(out, ignore_errors=True)
    argv = [sys.executable, "-m", "benchmarks.lerobot_acting", f"--policy.path={policy}", *flags,
            "--env.terminate_on_success=false", "--env.video_size=64", "--eval.n_episodes=5", "--eval.batch_size=1",
            "--policy.device=cpu", f"--output_dir={out}"]
    call(argv, log)
    timed = json.loads(log.read_text().strip().splitlines()[-1])
    return timed["actions"] / timed["seconds"]


def env_flags_of(command: list[str]) -> list[str]:
    """The env and seed flags of export_policy's lerobot-eval command: the env ours was evaluated in."""
    return [a for a in command if a.startswith(("--env.", "--seed="))]


def cell(env_id: str, inputs: str, args: argparse.Namespace) -> list[dict[str, Any]]:
    """One task and input: ours and each LeRobot policy at each budget, trained and evaluated."""
    from fetch.learn.evaluate import wilson

    seeing = f"pixels{args.image_size}-{args.image_quality}" if inputs == "pixels" else inputs
    root = pathlib.Path(args.dir).resolve() / env_id / seeing  # a cell per image size and quality
    root.mkdir(parents=True, exist_ok=True)
    log, records = root / "log.txt", Records(root / "records.json")
    missions = pathlib.Path(args.dir).resolve() / "mission"
    image = (["--inputs", "pixels", "--image-size", str(args.image_size), "--image-quality", args.image_quality]
             if inputs == "pixels" else [])
    stages = mission_dir(missions, env_id, args.style, inputs, args.image_size, args.image_quality)

    def mission() -> dict[str, Any]:
        call([sys.executable, "-m", "benchmarks.mission", "--env", env_id, "--style", args.style, "--seed",
              str(args.seed), "--episodes", str(args.episodes), "--dir", str(missions), *image,
              *shlex.split(args.mission_args)], log)
        return json.loads((stages / "timing.json").read_text())

    timing = records.get("mission", mission)
    budget = timing["train"]
    ours_eval = json.loads((stages / "eval.json").read_text())

    def export() -> str:
        merged, target = root / "merged.hdf5", root / "lerobot"
        sources = [str(p) for p in training_data(stages)]
        if len(sources) > 1:  # what `gym-fetch train` read as two datasets, one for LeRobot
            call([tool("gym-fetch"), "merge", *sources, "--out", str(merged), "--force"], log)
        # the images ours learnt from, drawn as its eval env draws them (the env every policy is scored in)
        cameras = ["--image-quality", args.image_quality] if inputs == "pixels" else ["--cameras", "none"]
        call([tool("gym-fetch"), "export", str(merged) if len(sources) > 1 else sources[0], "--to", "lerobot",
              "--repo-id", f"local/{env_id}-{inputs}", "--out", str(target), "--force", *cameras], log)
        merged.unlink(missing_ok=True)
        return str(target)

    dataset = records.get("export", export)

    def ours() -> dict[str, Any]:
        policy = root / "ours-policy"
        shutil.rmtree(policy, ignore_errors=True)
        printed = subprocess.run([sys.executable, "-m", "lerobot_env_fetch.export_policy", str(stages / "run"),
                                  str(policy)], capture_output=True, text=True, check=True).stdout
        command = printed.strip().splitlines()[-1].split()
        flags = env_flags_of(command)
        figures = lerobot_eval(policy, flags, root / "ours-eval", args.episodes, log)
        figures.update(env_flags=flags, policy=str(policy))
        return figures

    our = records.get("ours", ours)
    if our["successes"] != ours_eval["ever"]:
        print(f"  {env_id} {inputs}: lerobot-eval and gym-fetch eval DISAGREE on ours: "
              f"{sum(our['successes'])} against {sum(ours_eval['ever'])} of {args.episodes}")
    our_steps = int(checkpoint.read(stages / "run")["step"])
    rows = [{"key": "ours", "policy": "gym-fetch train", "budget": "its own", "train_s": budget, "steps": our_steps,
             "lerobot": our["pc_success"], "wins": sum(our["successes"]), "ours_last": ours_eval["success_rate"],
             "ours_ever": 100 * ours_eval["ever_success_rate"], "agree": our["successes"] == ours_eval["ever"],
             "path": root / "ours-policy"}]
    for name in args.policies:
        train_flags = [f"--dataset.repo_id=local/{env_id}-{inputs}", f"--dataset.root={dataset}", *COMMON,
                       *LEROBOT_POLICIES[name]]

        def probe(name: str = name, train_flags: list[str] = train_flags) -> float:
            out = root / f"{name}-probe"
            shutil.rmtree(out, ignore_errors=True)
            probe_log = root / f"{name}-probe.txt"
            probe_log.unlink(missing_ok=True)
            call([tool("lerobot-train"), *train_flags, f"--steps={PROBE_STEPS}", f"--log_freq={PROBE_LOG}",
                  f"--save_freq={PROBE_STEPS}", f"--output_dir={out}"], probe_log)
            shutil.rmtree(out)
            return seconds_per_step(probe_log.read_text())

        step_s = records.get(f"{name}-probe", probe)
        for scale in args.budgets:
            steps = max(1, round(scale * budget / step_s))
            key = f"{name}-{scale:g}x"

            def train_and_eval(key: str = key, steps: int = steps, train_flags: list[str] = train_flags
                               ) -> dict[str, Any]:
                out = root / key
                shutil.rmtree(out, ignore_errors=True)
                warmup = [f"--policy.scheduler_warmup_steps={min(500, steps // 10)}"] if "diffusion" in key else []
                wall = call([tool("lerobot-train"), *train_flags, *warmup, f"--steps={steps}", f"--save_freq={steps}",
                             f"--log_freq={max(1, steps // 20)}", f"--output_dir={out / 'train'}"], log)
                policy = out / "train/checkpoints/last/pretrained_model"
                figures = lerobot_eval(policy, our["env_flags"], out / "eval", args.episodes, log)
                figures.update(train_s=wall, steps=steps, policy=str(policy))
                return figures

            got = records.get(key, train_and_eval)
            rows.append({"key": key, "policy": {"act": "ACT", "diffusion": "Diffusion Policy"}[name],
                         "budget": f"{scale:g}x", "train_s": got["train_s"], "steps": got["steps"],
                         "lerobot": got["pc_success"], "wins": sum(got["successes"]), "ours_last": None,
                         "ours_ever": None, "agree": None,
                         "path": root / key / "train/checkpoints/last/pretrained_model"})
    for row in rows:  # after the cell's training, one at a time
        acting = root / f"{row['key']}-acting"
        row.update(task=env_id, inputs=inputs, interval=wilson(row["wins"], args.episodes),
                   rate=records.get(acting.name, lambda row=row, acting=acting: acting_rate(
                       row["path"], our["env_flags"], acting, root / f"{acting.name}.txt")))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", default="Bin-pick-v2,PickPlace-v2,Drawer-open-v2")
    parser.add_argument("--inputs", default="state,pixels", help="state, pixels or both, comma-separated")
    parser.add_argument("--style", default="person", help="the stand-in operator's style (benchmarks.mission)")
    parser.add_argument("--seed", type=int, default=100, help="the pad demos' collection seed")
    parser.add_argument("--policies", default="act,diffusion", help=f"of {', '.join(LEROBOT_POLICIES)}")
    parser.add_argument("--budgets", default="1,4", help="LeRobot's training time, as multiples of ours")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--image-size", type=int, default=DEFAULT_IMAGE_SIZE,
                        help=f"the camera cells' images' side [px] (default {DEFAULT_IMAGE_SIZE}, generate's)")
    parser.add_argument("--image-quality", default=DEFAULT_IMAGE_QUALITY, choices=IMAGE_QUALITIES,
                        help="the camera cells' rendering (benchmarks.mission)")
    parser.add_argument("--dir", default="/tmp/side_by_side")
    parser.add_argument("--mission-args", default="",
                        help="more benchmarks.mission flags, e.g. \"--demos 2 --generated 10\" (use another --dir)")
    args = parser.parse_args()
    args.policies = [p for p in args.policies.split(",") if p]
    unknown = sorted(set(args.policies) - set(LEROBOT_POLICIES))
    if unknown:
        parser.error(f"--policies: unknown {', '.join(unknown)}; choose from {', '.join(LEROBOT_POLICIES)}")
    args.budgets = [float(b) for b in args.budgets.split(",")]
    print(machine_line("torch", "lerobot"), flush=True)
    rows = [row for env_id in args.envs.split(",") for inputs in args.inputs.split(",")
            for row in cell(env_id, inputs, args)]
    print("\n| task | inputs | policy | training budget | training [min] | steps | success, lerobot-eval "
          "(95 % interval) | gym-fetch eval: at the last step / at some step | acting [actions/s] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        lo, hi = r["interval"]
        ours = (f"{100 * r['ours_last']:.0f} % / {r['ours_ever']:.0f} % ({'agrees' if r['agree'] else 'DIFFERS'})"
                if r["ours_ever"] is not None else "")
        print(f"| {r['task']} | {r['inputs']} | {r['policy']} | {r['budget']} | {r['train_s'] / 60:.1f} | "
              f"{r['steps'] or ''} | **{r['lerobot']:.0f} %** ({100 * lo:.0f}-{100 * hi:.0f}) | {ours} | "
              f"{r['rate']:.0f} |")


if __name__ == "__main__":
    main()
