"""`gym-fetch eval`: its flags, and the evaluation they ask for (`fetch.learn.jobs.evaluate_run`; torch is
imported only then)."""

from __future__ import annotations

import argparse

from fetch.looks import LOOKS


def add_eval_arguments(p: argparse.ArgumentParser) -> None:
    """`gym-fetch eval`'s flags."""
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
    p.add_argument("--act-steps", type=int, default=None, metavar="N",
                   help="a chunk policy predicts a chunk every N steps (1 to its chunk); default: as its run says "
                        "(cnn-chunk: 2; runs saved before that default: 1). To judge an older run as a new one acts")


def run(args: argparse.Namespace) -> int:
    from fetch.learn.jobs import EvalRequest, evaluate_run

    evaluate_run(EvalRequest(run_dir=args.run_dir, episodes=args.episodes, envs=args.envs, seed_start=args.seed_start,
                             video=args.video, videos=args.videos, camera=args.camera, json=args.json,
                             looks=args.looks, act_steps=args.act_steps))
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    e = sub.add_parser("eval", help="run a trained policy on seeds its dataset never used: success with a 95%% "
                                    "interval, mean episode length, videos")
    add_eval_arguments(e)
    e.set_defaults(run=run)
