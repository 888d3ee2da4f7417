"""`gym-fetch collect` (and `python -m fetch.collect`, and the original script `collect_fetch_demo.py`): its flags,
every device's own among them, and the session they ask for (`fetch.teleop.build.collect`, with a
`CollectRequest`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from fetch.cli import run_stoppable
from fetch.commands import flags


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The collector's flags: the original script's (same names and meaning) plus ours."""
    from fetch.dataset.formats import FORMATS
    from fetch.generate.room import STARTS
    from fetch.learn import device as _  # noqa: F401  (registers --device policy, from the layer above teleop)
    from fetch.learn import takeover as _takeover  # noqa: F401  (registers --device takeover)
    from fetch.tasks import ENV_IDS
    from fetch.teleop.config import RENDER_CHOICES
    from fetch.teleop.registry import DEVICE_NAMES, KINDS

    p.add_argument("--env", default="Bin-pick-v2", metavar="ID",
                   help=f"the task (default Bin-pick-v2), one of: {', '.join(ENV_IDS)}")
    flags.add_out(p, flags.COLLECT)
    p.add_argument("--episodes", type=int, default=0, help="demos to save in this session (default 0: until you quit)")
    flags.add_max_steps(p, flags.COLLECT)
    flags.add_seed(p)
    p.add_argument("--starts", default="all", choices=STARTS,
                   help="all (default): attempts from every start the env draws; tight: only from those where the "
                        "object stands close beside something along the fingers' axis (a bin's wall), as generate "
                        "--starts tight: attempt k then resets with the (k+1)-th such seed from --seed on. Where a "
                        "policy is weakest, for a correction round (--device takeover)")
    p.add_argument("--control-hz", type=float, default=None,
                   help="control rate [Hz]; default 25 (real time) with a person or a window, "
                        "as fast as possible for expert/scripted without a window; 0: as fast as possible")
    flags.add_success(p, flags.COLLECT)
    p.add_argument("--ignore-env-done", dest="ignore_env_done", action="store_true", default=False,
                   help="keep going when the env reports terminated (never past --max-steps)")
    p.add_argument("--respect-env-done", dest="ignore_env_done", action="store_false",
                   help="end the attempt when the env reports terminated (default)")
    p.add_argument("--keep-failures", action="store_true",
                   help="also save failed attempts (in mask/failed; default off)")
    p.add_argument("--render", default="auto", choices=RENDER_CHOICES,
                   help="auto (default): a window when there is a display; rgb_array (collect_fetch_demo.py's name) "
                        "is headless like none")
    p.add_argument("--device", default="gamepad", choices=DEVICE_NAMES,
                   help="what drives the arm (default gamepad): " + "; ".join(f"{k.name}: {k.summary}" for k in KINDS)
                        + ". Without a display or a pad: expert or scripted")
    p.add_argument("--format", default=FORMATS[0], choices=FORMATS,
                   help="hdf5 (default): robomimic's layout, replayable; npz: one file per demo, as "
                        "collect_fetch_demo.py wrote them")
    p.add_argument("--reward-type", default="sparse", choices=["sparse", "dense"],
                   help="sparse (default): -1 until the goal is reached, then 0; dense: minus the distance [m]")
    flags.add_images(p, flags.COLLECT)
    p.add_argument("--verbose", action="store_true", help="print how every attempt ended (default off)")
    for kind in KINDS:
        if kind.add_arguments is not None:
            kind.add_arguments(p.add_argument_group(f"--device {kind.name}"))


def run(args: argparse.Namespace) -> int:
    import fetch  # noqa: F401  (registers the ids)
    from fetch.teleop.build import CollectRequest, collect
    from fetch.teleop.registry import KINDS
    from fetch.teleop.session import CollectConfig

    # main() and collect_main() hold the stop handlers (fetch.stopping) around this.
    config = CollectConfig(
        env_id=args.env, out=args.out, episodes=args.episodes, max_steps=args.max_steps, seed=args.seed,
        starts=args.starts, control_hz=args.control_hz, success_hold_steps=args.success_hold_steps,
        stop_on_success=args.stop_on_success, ignore_env_done=args.ignore_env_done,
        keep_failures=args.keep_failures, device=args.device, render=args.render, format=args.format,
        reward_type=args.reward_type, cameras=flags.camera_list(args.cameras), image_size=args.image_size,
        image_quality=args.image_quality, verbose=args.verbose)
    devices = tuple(flags.options_of(kind.options, args) for kind in KINDS if kind.options is not None)
    return collect(CollectRequest(config, frame=args.frame, devices=devices))


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    c = sub.add_parser("collect", help="record demonstrations (gamepad, keyboard, scripted or expert)")
    add_arguments(c)
    c.set_defaults(run=run)


def collect_main(argv: Sequence[str] | None = None, prog: str = "collect_fetch_demo.py") -> int:
    """`gym-fetch collect` under another name (the original script): its usage and errors say `prog`."""
    p = argparse.ArgumentParser(prog=prog, description="Record demonstrations: the original collection script, "
                                "every flag with its meaning; the same as `gym-fetch collect`.")
    add_arguments(p)
    p.set_defaults(run=run, command="collect")
    return run_stoppable(lambda: p.parse_args(argv), prog)


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m fetch.collect ARGS`: `gym-fetch collect ARGS`."""
    from fetch.cli import main as cli_main

    return cli_main(["collect", *(sys.argv[1:] if argv is None else argv)])
