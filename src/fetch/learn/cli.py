"""`gym-fetch train` and `gym-fetch eval`: their flags and what they run (torch is imported only then)."""

from __future__ import annotations

import argparse
import json
import pathlib

from fetch._progress import said_if_slow
from fetch.errors import FetchError
from fetch.learn import (
    DEFAULT_STEPS,
    MEASURED_MIRROR,
    MEASURED_POLICY,
    MEASURED_SETTINGS,
    MEASURED_STEPS,
    POLICY_KINDS,
    TORCH_INSTALL,
    auto_settings,
    default_steps,
    require_torch,
)
from fetch.tasks import mirroring_ids


def _auto_tasks(setting: str) -> str:
    """The tasks on which `--policy auto` turns `setting` on (fetch.learn.MEASURED_SETTINGS)."""
    return ", ".join(sorted(task for task, settings in MEASURED_SETTINGS.items() if settings.get(setting)))


def _blind_tasks() -> list[str]:
    """The tasks on which `--policy auto` leaves the velocities out (fetch.learn.MEASURED_SETTINGS)."""
    return sorted(task for task, settings in MEASURED_SETTINGS.items() if settings.get("velocities") is False)


FROM_STEPS_DIVISOR = 4
FROM_STEPS = "quarter"
"""`train --from RUN` goes on for a quarter of RUN's steps unless --steps says otherwise."""
CORRECTION_WEIGHT = 4
"""The default `--correction-weight`."""


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", nargs="+",
                   help="a dataset directory (from gym-fetch collect) or file (e.g. from merge); several of one task "
                        "are learnt from together (the demos and the attempts a person corrected)")
    p.add_argument("--from", dest="start_from", default=None, metavar="RUN",
                   help="go on training RUN's policy (its settings, weights and input normalisation) on these "
                        "datasets, e.g. the original demos plus the corrected attempts of `collect --device takeover` "
                        f"(default steps: a {FROM_STEPS} of RUN's)")
    p.add_argument("--correction-weight", type=int, default=CORRECTION_WEIGHT,
                   help="how many times each stretch a person drove in a corrected attempt is repeated among the "
                        f"training demos (default {CORRECTION_WEIGHT})")
    p.add_argument("--out", required=True, metavar="RUN",
                   help="the run directory: its checkpoint.pt is written atomically every --checkpoint-every steps; "
                        "run the same command again to resume a run that was stopped")
    p.add_argument("--policy", default="auto", choices=("auto", *POLICY_KINDS),
                   help="auto (default): the policy measured best on the dataset's task, gru but for "
                        f"{', '.join(sorted(MEASURED_POLICY))} (mlp-chunk), an ensemble of 5 on "
                        f"{_auto_tasks('members')}, "
                        "goal offsets, velocities, chunks and mirror images where --goal-offsets, --velocities, "
                        "--chunk and --mirror say "
                        "(docs/learning_curves.md); gru: a "
                        "recurrent policy (BC-RNN); mlp-chunk: an MLP predicting chunks of actions with ACT's "
                        "temporal ensembling, ~7x faster to train")
    p.add_argument("--seed", type=int, default=0, help="seed of the initial weights and the batches (default 0)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--steps", type=int, default=None,
                        help=f"gradient steps (default {DEFAULT_STEPS}; "
                             + ", ".join(f"{n} on {t}" for t, n in sorted(MEASURED_STEPS.items())) + ")")
    length.add_argument("--epochs", type=int, default=None,
                        help="passes over the training examples, instead of --steps")
    p.add_argument("--demos", type=int, default=0, help="train on the first N demos of mask/train (default 0: all)")
    p.add_argument("--batch-size", type=int, default=256, help="examples per step (default 256)")
    p.add_argument("--lr", type=float, default=1e-3, help="peak learning rate, cosine decay to 0 (default 1e-3)")
    p.add_argument("--chunk", type=int, default=None,
                   help="mlp-chunk: actions per prediction (default 10; --policy auto: "
                        + ", ".join(f"{settings['chunk']} on {task}"
                                    for task, settings in sorted(MEASURED_SETTINGS.items()) if "chunk" in settings)
                        + ")")
    p.add_argument("--seq-len", type=int, default=None, help="gru: training window [steps] (default 10)")
    p.add_argument("--hidden", type=int, default=None, help="units per layer (default 256; gru 128)")
    p.add_argument("--layers", type=int, default=None, help="hidden layers (default 2; gru 1)")
    p.add_argument("--members", type=int, default=None,
                   help="an ensemble: train this many networks side by side from different initial weights "
                        "and act on their mean; takes that many times as long (default 1; --policy auto: 5 on "
                        f"{_auto_tasks('members')})")
    p.add_argument("--goal-offsets", action=argparse.BooleanOptionalAction, default=None,
                   help="also feed the policy the goal relative to the achieved goal and to the grip site "
                        "(6 more inputs; default off; --policy auto: on for "
                        f"{_auto_tasks('goal_offsets')})")
    p.add_argument("--velocities", action=argparse.BooleanOptionalAction, default=None,
                   help="let the policy see the velocities in the observation (default on; --policy auto: off "
                        f"for {', '.join(_blind_tasks())}): without them it acts on where things are, and does not "
                        "learn to go on doing what it did a moment ago from demos of uneven pace (docs/operators.md)")
    p.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                   help="also learn from each demo's mirror image in the vertical plane through the start "
                        f"(tasks symmetric about it: {', '.join(mirroring_ids())}; "
                        f"default off; --policy auto: on for {', '.join(sorted(MEASURED_MIRROR))})")
    p.add_argument("--obs-noise", type=float, default=0.0,
                   help="std of noise on the normalised observations while training (default 0)")
    p.add_argument("--checkpoint-every", type=int, default=1000,
                   help="steps between checkpoints and validation losses (default 1000)")
    p.add_argument("--threads", type=int, default=1,
                   help="torch threads (default 1; results are reproducible for a given count)")


def run_train(args: argparse.Namespace) -> int:
    require_torch()
    from fetch.dataset.habits import layout_of
    from fetch.learn.data import load_many, velocity_columns
    from fetch.learn.policies import KIND_DEFAULTS
    from fetch.learn.train import TrainConfig, base_settings, train

    with said_if_slow(f"reading {', '.join(args.dataset)} ..."):
        demos = load_many(args.dataset, args.correction_weight)
    if args.start_from is not None:
        policy, before = base_settings(args.start_from)
        given = [f"--{n.replace('_', '-')}" for n in ("chunk", "seq_len", "hidden", "layers", "members", "goal_offsets",
                                                     "velocities") if getattr(args, n) is not None]
        if given or args.policy != "auto":
            raise FetchError(f"--from {args.start_from} goes on with that run's policy; leave out "
                             f"{', '.join(given) or '--policy'}")
        kind = policy["kind"]
        args.mirror = before.get("mirror", False) if args.mirror is None else args.mirror
        args.steps = args.steps if args.steps is not None else max(1, int(before["steps"]) // FROM_STEPS_DIVISOR)
    else:
        chosen = auto_settings(demos.env_id) if args.policy == "auto" else {"kind": args.policy}
        kind = chosen["kind"]
        policy = {**KIND_DEFAULTS.get(kind, {}), **chosen}
        for name in ("chunk", "seq_len", "hidden", "layers", "members", "goal_offsets"):
            if getattr(args, name) is not None:
                policy[name] = getattr(args, name)
        velocities = policy.pop("velocities", True)
        velocities = velocities if args.velocities is None else args.velocities
        if not velocities:
            policy["blind"] = velocity_columns(layout_of(demos.env_id) or {})
    if kind == "gru" and args.chunk is not None:
        raise FetchError(f"--chunk is for --policy mlp-chunk; {args.policy} trains gru here, which predicts one "
                         "action per step")
    if kind == "mlp-chunk" and args.seq_len is not None:
        raise FetchError(f"--seq-len is for --policy gru; {args.policy} trains mlp-chunk here, which reads one "
                         "observation")
    mirror = args.mirror if args.mirror is not None else args.policy == "auto" and demos.env_id in MEASURED_MIRROR
    steps = args.steps if args.steps is not None else default_steps(demos.env_id)
    if args.epochs is not None:
        if args.epochs < 1:
            raise FetchError(f"--epochs must be a whole number >= 1, got {args.epochs}")
        used = demos.train[:args.demos] if args.demos else demos.train
        count = sum(len(e.actions) for e in used)
        steps = args.epochs * max(1, count // max(1, min(args.batch_size, count)))
    config = TrainConfig(steps=steps, batch_size=args.batch_size, lr=args.lr, obs_noise=args.obs_noise,
                         seed=args.seed, demos=args.demos, mirror=mirror, checkpoint_every=args.checkpoint_every,
                         threads=args.threads)
    result = train(demos, args.out, policy, config, start_from=args.start_from)
    valid = "none (no valid split)" if result.valid_loss is None else f"{result.valid_loss:.4f}"
    resumed = f", resumed at step {result.resumed_from}" if result.resumed_from else ""
    members = f" ({policy['members']} members)" if policy.get("members", 1) > 1 else ""
    mirrored = " and their mirror images" if mirror else ""
    mirrored += ", not seeing velocities" if policy.get("blind") else ""
    print(f"trained {kind}{members} on {len(demos.train[:args.demos or None])} {demos.env_id} demos{mirrored} for "
          f"{result.steps} steps{resumed}: train loss {result.train_loss:.4f}, valid loss {valid}; "
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
