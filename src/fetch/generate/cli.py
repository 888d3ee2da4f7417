"""The `gym-fetch generate` and `gym-fetch subtasks` subcommands (wired into `fetch.cli`)."""

from __future__ import annotations

import argparse
import pathlib
from typing import Any

from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.dataset.reader import FILE_HELP
from fetch.generate.attempt import STARTS
from fetch.looks import LOOKS
from fetch.rendering import CAMERAS, DEFAULT_IMAGE_QUALITY, IMAGE_QUALITIES, QUALITY_HELP

SUBTASKS_HELP = "cut a dataset's demos into their task's subtasks and print where each begins"


def add_generate_parser(sub: Any) -> None:
    g = sub.add_parser("generate", help="generate many demos from a few (object-centric, MimicGen-style)",
                       description="Cut each source demo into its task's object-centric subtasks, then for each new "
                                   "episode carry one source segment per subtask over to the objects' new poses, "
                                   "execute it and keep the successes. The output is an ordinary dataset; run the "
                                   "same command again after an interruption to finish it.")
    g.add_argument("--source", required=True, help="the dataset to generate from (a directory or demos.hdf5)")
    g.add_argument("--out", required=True, help="the output directory (a dataset like collect's)")
    g.add_argument("--demos", type=int, required=True, help="how many demos --out should hold")
    g.add_argument("--seed", type=int, default=0, help="attempt n resets with seed + n (default 0)")
    g.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core)")
    g.add_argument("--ray", nargs="?", const="auto", default=None, metavar="ADDRESS",
                   help="run attempts as Ray actors on a cluster (default address: auto, the cluster this "
                        "machine belongs to; 'local' starts one here)")
    g.add_argument("--max-steps", type=int, default=None,
                   help="steps per attempt (default: the env's horizon, or more where the source demos, their "
                        "idle steps left out, need it)")
    g.add_argument("--success-hold-steps", type=int, default=5,
                   help="success must hold over an attempt's last this many steps (default 5)")
    g.add_argument("--stop-on-success", action=argparse.BooleanOptionalAction, default=False,
                   help="end an attempt once success has held --success-hold-steps (MimicGen's demos end there; "
                        "default off: every attempt runs to --max-steps, the last segment to its source's end and "
                        "then holding still, so a policy learns to stay done)")
    g.add_argument("--selection", default="nearest", help="source segment choice: nearest (default) or random")
    g.add_argument("--nearest-k", type=int, default=3, help="choose among this many nearest segments (default 3)")
    g.add_argument("--noise", type=float, default=0.1,
                   help="std of the noise on the executed arm action, action units (0.1: 5 mm of hand target); the "
                        "clean action is recorded as expert_actions, what training learns (DART; default %(default)s; "
                        "0: none)")
    g.add_argument("--finger-noise", type=float, default=None, metavar="STD",
                   help="std of the noise on a[3], metres of finger target (a finger travels 0.05); default --noise "
                        "(0.1: the fingers swing open and shut; 0.005 is the hand's metres)")
    g.add_argument("--retries", type=int, default=1,
                   help="times an attempt may make a grasp again whose object is not held at the end of the segment "
                        "after it (open, come back, grasp again), so that demos show recoveries "
                        "(default %(default)s; 0: never)")
    g.add_argument("--fit-opening", action=argparse.BooleanOptionalAction, default=True,
                   help="coming down on an object, open the fingers no wider than puts each midway between it and "
                        "whatever stands beside it (a bin's wall), where the source opened them wider (default on)")
    g.add_argument("--steady-fit", action=argparse.BooleanOptionalAction, default=True,
                   help="where --fit-opening narrowed an approach, perturb the fingers during it by the hand's metres "
                        "(--noise x 0.05), not --finger-noise, so that they come down as narrow as asked (default on)")
    g.add_argument("--starts", default="all", choices=STARTS,
                   help="all (default): attempts from every start the env draws; tight: only from those where the "
                        "object stands close beside something along the fingers' axis (a bin's wall), skipping the "
                        "rest: a second dataset of those rare starts to train on beside the first (docs/generate.md)")
    g.add_argument("--max-attempts", type=int, default=None, help="give up after this many (default 50 per demo)")
    g.add_argument("--cameras", default="",
                   help=f"record these cameras' images too, comma-separated ({', '.join(CAMERAS)}), rendered from "
                        "each demo's states in the workers as collect --cameras records them; default none")
    g.add_argument("--image-size", type=int, default=DEFAULT_IMAGE_SIZE,
                   help=f"recorded image width and height [px] (default {DEFAULT_IMAGE_SIZE})")
    g.add_argument("--image-quality", default=DEFAULT_IMAGE_QUALITY, choices=IMAGE_QUALITIES, help=QUALITY_HELP)
    g.add_argument("--looks", default=None, choices=LOOKS,
                   help="plain: the scene as modelled; random: each demo's colours, lights and camera mounts drawn "
                        "from its reset seed (visual randomisation, for pixel policies; docs/rendering.md); "
                        "default: the source dataset's")
    g.set_defaults(run=run_generate)
    s = sub.add_parser("subtasks", help=SUBTASKS_HELP)
    s.add_argument("file", help=FILE_HELP)
    s.add_argument("--demo", default=None, help="a demo index or name (default: all)")
    s.set_defaults(run=run_subtasks)


def run_generate(args: argparse.Namespace) -> int:
    from fetch.generate.attempt import Options
    from fetch.generate.run import GenerateConfig, generate

    options = Options(max_steps=args.max_steps, success_hold_steps=args.success_hold_steps, selection=args.selection,
                      nearest_k=args.nearest_k, noise=args.noise, finger_noise=args.finger_noise,
                      stop_on_success=args.stop_on_success, retries=args.retries, fit_opening=args.fit_opening,
                      steady_fit=args.steady_fit, starts=args.starts)
    cameras = tuple(c.strip() for c in args.cameras.split(",") if c.strip())  # as collect's --cameras
    config = GenerateConfig(source=args.source, out=args.out, demos=args.demos, seed=args.seed,
                            workers=args.workers, options=options, max_attempts=args.max_attempts, ray=args.ray,
                            cameras=cameras, image_size=args.image_size, image_quality=args.image_quality,
                            looks=args.looks)
    summary = generate(config)
    print(summary.describe())
    if not summary.gave_up and summary.total:
        name = pathlib.PurePath(args.out).name or "generated"
        print(f"next: train a policy on them with `gym-fetch train {args.out} --out runs/{name}`")
    return 1 if summary.gave_up else 0


def run_subtasks(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from fetch.dataset.reader import open_dataset
    from fetch.dataset.validation import require_valid
    from fetch.generate.segments import annotate

    with open_dataset(args.file) as ds:
        names = ds.select(args.demo)
        require_valid(ds, names, images=False)
        env: Any = gym.make(ds.env_id, **ds.env_kwargs).unwrapped
        subtasks = type(env.task).subtasks
        print(f"{ds.env_id}: subtasks {', '.join(s.name for s in subtasks)}")
        for name in names:
            arrays = ds.arrays(name)
            a = annotate(env, subtasks, arrays["states"], arrays["actions"][:, 3])
            parts = ", ".join(f"{subtasks[k].name} {lo}-{hi - 1}" for k, (lo, hi) in enumerate(a.bounds()))
            print(f"{name}: {parts}" + ("" if a.complete else " (incomplete: not every subtask ended)"))
    return 0
