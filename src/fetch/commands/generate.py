"""`gym-fetch generate`: its flags, and the generation run they ask for (`fetch.generate.run.generate`, with a
`GenerateConfig`)."""

from __future__ import annotations

import argparse
import pathlib

from fetch.commands import flags
from fetch.generate.room import STARTS
from fetch.looks import LOOKS


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    g = sub.add_parser("generate", help="generate many demos from a few (object-centric, MimicGen-style)",
                       description="Cut each source demo into its task's object-centric subtasks, then for each new "
                                   "episode carry one source segment per subtask over to the objects' new poses, "
                                   "execute it and keep the successes. The output is an ordinary dataset; run the "
                                   "same command again after an interruption to finish it.")
    g.add_argument("--source", required=True, help="the dataset to generate from (a directory or demos.hdf5)")
    flags.add_out(g, flags.GENERATE)
    g.add_argument("--demos", type=int, required=True, help="how many demos --out should hold")
    flags.add_seed(g)
    g.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core)")
    g.add_argument("--ray", nargs="?", const="auto", default=None, metavar="ADDRESS",
                   help="run attempts as Ray actors on a cluster (default address: auto, the cluster this "
                        "machine belongs to; 'local' starts one here)")
    flags.add_max_steps(g, flags.GENERATE)
    flags.add_success(g, flags.GENERATE)
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
    g.add_argument("--hand-response", type=float, default=None, metavar="SHARE",
                   help="the share of a commanded step the hand is taken to cover: each step commands its distance "
                        "to the carried-over path divided by it (1: the hand, covering 0.64, trails a moving path by "
                        "1-1.5 cm; 0.64 follows it; default: 0.64 on Drawer-close-v2, 1 elsewhere; docs/generate.md)")
    g.add_argument("--max-attempts", type=int, default=None, help="give up after this many (default 50 per demo)")
    flags.add_images(g, flags.GENERATE)
    g.add_argument("--looks", default=None, choices=LOOKS,
                   help="plain: the scene as modelled; random: each demo's colours, lights and camera mounts drawn "
                        "from its reset seed (visual randomisation, for pixel policies; docs/rendering.md); "
                        "default: the source dataset's")
    g.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from fetch.generate.attempt import Options
    from fetch.generate.run import GenerateConfig, generate

    options = Options(max_steps=args.max_steps, success_hold_steps=args.success_hold_steps, selection=args.selection,
                      nearest_k=args.nearest_k, noise=args.noise, finger_noise=args.finger_noise,
                      stop_on_success=args.stop_on_success, retries=args.retries, fit_opening=args.fit_opening,
                      steady_fit=args.steady_fit, starts=args.starts,
                      hand_response=args.hand_response)
    config = GenerateConfig(source=args.source, out=args.out, demos=args.demos, seed=args.seed,
                            workers=args.workers, options=options, max_attempts=args.max_attempts, ray=args.ray,
                            cameras=flags.camera_list(args.cameras), image_size=args.image_size,
                            image_quality=args.image_quality, looks=args.looks)
    summary = generate(config)
    print(summary.describe())
    if not summary.gave_up and summary.total:
        name = pathlib.PurePath(args.out).name or "generated"
        print(f"next: train a policy on them with `gym-fetch train {args.out} --out runs/{name}`")
    return 1 if summary.gave_up else 0
