"""`gym-fetch train` and `gym-fetch eval`: their flags and what they run (torch is imported only then)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
from collections.abc import Callable
from typing import Any

from fetch._progress import said_if_slow
from fetch.errors import FetchError
from fetch.learn import TORCH_INSTALL, require_torch
from fetch.learn.kinds import FINGER_SCALE, FINGER_SPAN, INPUTS, KINDS, POLICY_KINDS
from fetch.learn.settings import ACCELERATORS, AUTO, CORRECTION_WEIGHT, PRECISIONS, TrainRequest, sees_pixels
from fetch.looks import LOOKS
from fetch.tasks import REGISTRATIONS, Training, mirroring_ids


def _auto_tasks(differs: Callable[[Training], Any]) -> str:
    """The tasks whose training defaults (the task table's `Training`) `differs` picks out, comma-separated."""
    return ", ".join(r.env_id for r in REGISTRATIONS if differs(r.training))


def _auto_values(field: str) -> str:
    """'VALUE on TASK, ...' for the tasks whose default for `field` is not `Training`'s."""
    plain = getattr(Training(), field)
    return ", ".join(f"{getattr(r.training, field)} on {r.env_id}" for r in REGISTRATIONS
                     if getattr(r.training, field) not in (plain, None))


def _pixel_training(field: str) -> Any:
    """The pixel kind's default for a training setting."""
    return next(k.training[field] for k in KINDS if k.inputs == "pixels")


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", nargs="+",
                   help="a dataset directory (from gym-fetch collect) or file (e.g. from merge); several of one task "
                        "are learnt from together (the demos and the attempts a person corrected)")
    p.add_argument("--from", dest="start_from", default=None, metavar="RUN",
                   help="go on training RUN's policy (its settings, weights and input normalisation) on these "
                        "datasets, e.g. the original demos plus the corrected attempts of `collect --device takeover` "
                        "(default steps: a quarter of RUN's)")
    p.add_argument("--correction-weight", type=int, default=CORRECTION_WEIGHT,
                   help="how many times each stretch a person drove in a corrected attempt is repeated among the "
                        f"training demos (default {CORRECTION_WEIGHT})")
    p.add_argument("--out", required=True, metavar="RUN",
                   help="the run directory: its checkpoint.pt is written atomically every --checkpoint-every steps; "
                        "run the same command again to resume a run that was stopped")
    p.add_argument("--policy", default=AUTO, choices=(AUTO, *POLICY_KINDS),
                   help=f"{AUTO} (default): what measured best on the dataset's task (its line in the task table, "
                        f"docs/training.md): {Training().policy}, but {_auto_values('policy')}; an ensemble of "
                        f"{_auto_values('members')}; goal offsets, velocities, chunks and mirror images where "
                        "--goal-offsets, --velocities, --chunk and --mirror say. "
                        + "; ".join(f"{k.name}: {k.summary}" for k in KINDS))
    p.add_argument("--inputs", default="state", choices=INPUTS,
                   help="what the policy sees: state (default): the observation and the goal; pixels: the camera "
                        "images the dataset holds (collect/generate --cameras, render-obs), the robot's own readings "
                        "(hand position and velocity, finger opening) and the goal, nothing of the objects' state "
                        "(--policy auto: cnn-chunk; docs/training.md)")
    p.add_argument("--cameras", type=_camera_list, default=None, metavar="NAMES",
                   help="--inputs pixels: the cameras it sees, comma-separated (default: every camera the dataset "
                        "has images of)")
    p.add_argument("--seed", type=int, default=0, help="seed of the initial weights and the batches (default 0)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--steps", type=int, default=None,
                        help=f"gradient steps (default {Training().steps}; {_auto_values('steps')}; --inputs pixels "
                             f"{_pixel_training('steps')})")
    length.add_argument("--epochs", type=int, default=None,
                        help="passes over the training examples, instead of --steps")
    p.add_argument("--demos", type=int, default=0, help="train on the first N demos of mask/train (default 0: all)")
    p.add_argument("--batch-size", type=int, default=None,
                   help=f"examples per step (default 256; --inputs pixels {_pixel_training('batch_size')})")
    p.add_argument("--lr", type=float, default=1e-3, help="peak learning rate, cosine decay to 0 (default 1e-3)")
    p.add_argument("--chunk", type=int, default=None,
                   help=f"mlp-chunk: actions per prediction (default 10; --policy auto: {_auto_values('chunk')})")
    p.add_argument("--seq-len", type=int, default=None, help="gru: training window [steps] (default 10)")
    p.add_argument("--finger-scale", type=float, default=None,
                   help=f"learn the fingers' action a[3] companded, |a[3]| up to this [m of finger target] "
                        f"spanning +-{FINGER_SPAN}, the squeeze -1 (default {FINGER_SCALE}, a finger's travel; "
                        f"0: as recorded)")
    p.add_argument("--hidden", type=int, default=None, help="units per layer (default 256; gru 128)")
    p.add_argument("--layers", type=int, default=None, help="hidden layers (default 2; gru 1)")
    p.add_argument("--members", type=int, default=None,
                   help="an ensemble: train this many networks side by side from different initial weights "
                        "and act on their mean; takes that many times as long (default 1; --policy auto: 5 on "
                        f"{_auto_tasks(lambda t: t.members > 1)})")
    p.add_argument("--goal-offsets", action=argparse.BooleanOptionalAction, default=None,
                   help="also feed the policy the goal relative to the achieved goal and to the grip site "
                        "(6 more inputs; default off; --policy auto: on for "
                        f"{_auto_tasks(lambda t: t.goal_offsets)})")
    p.add_argument("--velocities", action=argparse.BooleanOptionalAction, default=None,
                   help="let the policy see the velocities in the observation (a pixel policy: the robot's own; "
                        f"default on; --policy auto: off for {_auto_tasks(lambda t: not t.velocities)}): without them "
                        "it acts on where things are, and does not learn to go on doing what it did a moment ago "
                        "from demos of uneven pace (docs/operators.md)")
    p.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                   help="also learn from each demo's mirror image in the vertical plane through the start "
                        f"(tasks symmetric about it: {', '.join(mirroring_ids())}; "
                        f"default off; --policy auto: on for {_auto_tasks(lambda t: t.mirror)})")
    p.add_argument("--obs-noise", type=float, default=0.0,
                   help="std of noise on the normalised observations while training (default 0)")
    p.add_argument("--checkpoint-every", type=int, default=1000,
                   help="steps between checkpoints and validation losses (default 1000)")
    p.add_argument("--accelerator", default="auto", choices=ACCELERATORS,
                   help="where to train: auto (default) is CUDA where torch sees a GPU, else the CPU; running a "
                        "policy stays on the CPU (docs/training.md)")
    p.add_argument("--precision", default=None, choices=PRECISIONS,
                   help="fp32, or bf16 (mixed precision: matrix products and convolutions in bfloat16, weights in "
                        "fp32); auto is bf16 where the CPU or GPU computes it natively (default fp32; --inputs "
                        "pixels auto)")
    p.add_argument("--threads", type=int, default=None,
                   help="torch threads, 0 for one per core (default 1; --inputs pixels 0; results are reproducible "
                        "for a given count)")


def _camera_list(text: str) -> tuple[str, ...]:
    return tuple(c.strip() for c in text.split(",") if c.strip())


def run_train(args: argparse.Namespace) -> int:
    require_torch()
    from fetch.learn import checkpoint
    from fetch.learn.data import load_many
    from fetch.learn.train import train

    request = TrainRequest(**{f.name: getattr(args, f.name) for f in dataclasses.fields(TrainRequest)})
    base = checkpoint.read(request.start_from) if request.start_from is not None else None
    with said_if_slow(f"reading {', '.join(args.dataset)} ..."):
        demos = load_many(args.dataset, args.correction_weight, images=sees_pixels(request, base))
    result = train(demos, args.out, request)
    policy, config = result.plan.policy, result.plan.config
    valid = "none (no valid split)" if result.valid_loss is None else f"{result.valid_loss:.4f}"
    resumed = f", resumed at step {result.resumed_from}" if result.resumed_from else ""
    members = f" ({policy.members} members)" if policy.members > 1 else ""
    mirrored = " and their mirror images" if config.mirror else ""
    mirrored += f", seeing {', '.join(policy.cameras)}" if policy.cameras else ""
    mirrored += ", not seeing velocities" if policy.blind and not policy.cameras else ""
    print(f"trained {policy.kind}{members} on {len(demos.train[:config.demos or None])} {demos.env_id} demos"
          f"{mirrored} for {result.steps} steps{resumed}: train loss {result.train_loss:.4f}, valid loss {valid}; "
          f"evaluate with: gym-fetch eval {args.out}")
    return 0


def add_eval_arguments(p: argparse.ArgumentParser) -> None:
    from fetch.learn.evaluate import EVAL_SEED_START

    p.add_argument("run_dir", metavar="RUN", help="a run directory from gym-fetch train")
    p.add_argument("--episodes", type=int, default=100, help="episodes to run (default 100)")
    p.add_argument("--envs", type=int, default=50, help="episodes stepped at once (default 50)")
    p.add_argument("--seed-start", type=int, default=EVAL_SEED_START,
                   help=f"evaluation seeds count up from here, skipping the dataset's (default {EVAL_SEED_START})")
    p.add_argument("--video", default=None, metavar="DIR", help="also write mp4s of the first --videos episodes here")
    p.add_argument("--videos", type=int, default=3, help="how many episodes --video records (default 3)")
    p.add_argument("--camera", default="front", help="the videos' camera: front (default), side, behind or wrist")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the per-episode results as JSON")
    p.add_argument("--looks", default=None, choices=LOOKS,
                   help="the scene's looks in the episodes' images: plain (as modelled) or random (colours, lights "
                        "and camera mounts drawn per episode from its seed, so unseen ones; docs/rendering.md); "
                        "default: those of the policy's training data")


def run_eval(args: argparse.Namespace) -> int:
    require_torch()
    from fetch.learn.evaluate import evaluate, record_videos
    from fetch.learn.runtime import load

    if args.seed_start < 0:
        raise FetchError(f"--seed-start must be a whole number >= 0, got {args.seed_start}")
    if args.video is not None and args.videos < 1:
        raise FetchError(f"--videos must be a whole number >= 1, got {args.videos}")
    if args.video is not None:
        from fetch.dataset.video import require_pyav

        require_pyav()  # before the episodes, not after them
    policy = load(args.run_dir)
    if args.looks is not None:
        policy.env_kwargs = {**policy.env_kwargs, "looks": args.looks}
    if args.video is not None:
        from fetch.dataset.frames import check_env_camera

        check_env_camera(policy.env_id, policy.env_kwargs, args.camera)
    result = evaluate(policy, args.episodes, envs=args.envs, seed_start=args.seed_start)
    print(result.describe())
    if args.json is not None:
        pathlib.Path(args.json).write_text(json.dumps(result.as_dict(), indent=1))
    if args.video is not None:
        written = record_videos(policy, list(result.seeds[:args.videos]), args.video, camera=args.camera)
        print(f"videos: {', '.join(str(p) for p in written)}")
    return 0


def add_learn_parsers(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """The `train` and `eval` subcommands."""
    t = sub.add_parser("train", help=f"train a policy on a dataset (needs torch: {TORCH_INSTALL})")
    add_train_arguments(t)
    t.set_defaults(run=run_train)
    e = sub.add_parser("eval", help="run a trained policy on seeds its dataset never used: success with a 95%% "
                                    "interval, mean episode length, videos")
    add_eval_arguments(e)
    e.set_defaults(run=run_eval)
