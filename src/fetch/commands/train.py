"""`gym-fetch train`: its flags, and the training job they ask for (`fetch.learn.jobs.train_datasets`; torch
is imported only then)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from fetch.commands import flags
from fetch.learn import TORCH_INSTALL
from fetch.learn.kinds import AUTO, FINGER_SCALE, FINGER_SPAN, INPUTS, KINDS, POLICY_KINDS, pixel_kind
from fetch.learn.recipes import Training, task_training
from fetch.learn.settings import ACCELERATORS, CORRECTION_WEIGHT, PRECISIONS, TrainRequest
from fetch.tasks import ENV_IDS, mirroring_ids


def _auto_tasks(differs: Callable[[Training], Any]) -> str:
    """The tasks whose training defaults (their recipe, `fetch.learn.recipes`) `differs` picks out, comma-separated."""
    return ", ".join(env_id for env_id in ENV_IDS if differs(task_training(env_id)))


def _auto_values(field: str) -> str:
    """'VALUE on TASK, ...' for the tasks whose default for `field` is not `Training`'s."""
    plain = getattr(Training(), field)
    return ", ".join(f"{getattr(task_training(env_id), field)} on {env_id}" for env_id in ENV_IDS
                     if getattr(task_training(env_id), field) not in (plain, None))


def _pixel_training(field: str) -> Any:
    """The pixel kind's default for a training setting."""
    return pixel_kind().training[field]


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    """`gym-fetch train`'s flags."""
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
    p.add_argument("--cameras", type=flags.camera_list, default=None, metavar="NAMES",
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


def run(args: argparse.Namespace) -> int:
    from fetch.learn.jobs import TrainJob, train_datasets

    request = flags.request_of(TrainRequest, args)
    print(train_datasets(TrainJob(tuple(args.dataset), args.out, request, args.correction_weight)))
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    t = sub.add_parser("train", help=f"train a policy on a dataset (needs torch: {TORCH_INSTALL})")
    add_train_arguments(t)
    t.set_defaults(run=run)
