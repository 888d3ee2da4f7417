"""`gym-fetch collect` (and `python -m fetch.collect`, and the original script `collect_fetch_demo.py`): its flags,
every device's own among them, and the run."""

from __future__ import annotations

import argparse
import pathlib
import sys
from collections.abc import Sequence

from fetch.cli import run_stoppable


def add_collect_arguments(p: argparse.ArgumentParser) -> None:
    """The collector's flags: the original script's (same names and meaning) plus ours."""
    from fetch.dataset.formats import FORMATS
    from fetch.learn import device as _  # noqa: F401  (registers --device policy, from the layer above teleop)
    from fetch.learn import takeover as _takeover  # noqa: F401  (registers --device takeover)
    from fetch.rendering import DEFAULT_IMAGE_QUALITY, IMAGE_QUALITIES, QUALITY_HELP
    from fetch.tasks import ENV_IDS
    from fetch.teleop.config import RENDER_CHOICES
    from fetch.teleop.registry import DEVICE_NAMES, KINDS

    p.add_argument("--env", default="Bin-pick-v2", metavar="ID",
                   help=f"the task (default Bin-pick-v2), one of: {', '.join(ENV_IDS)}")
    p.add_argument("--out", default="demos",
                   help="output directory (default demos; resumed if it holds a matching dataset)")
    p.add_argument("--episodes", type=int, default=0, help="demos to save in this session (default 0: until you quit)")
    p.add_argument("--max-steps", type=int, default=None,
                   help="steps per attempt at most (default 500, replacing the 50-step training limit; for "
                        "the expert the task's horizon, 50)")
    p.add_argument("--seed", type=int, default=0,
                   help="attempt k of the dataset resets with seed + k (default 0; a whole number >= 0)")
    p.add_argument("--control-hz", type=float, default=None,
                   help="control rate [Hz]; default 25 (real time) with a person or a window, "
                        "as fast as possible for expert/scripted without a window; 0: as fast as possible")
    p.add_argument("--success-hold-steps", type=int, default=10,
                   help="steps success must hold before the attempt ends (default 10)")
    p.add_argument("--stop-on-success", action=argparse.BooleanOptionalAction, default=None,
                   help="end the attempt once success has held (default on; off for the expert, whose demos "
                        "run to the task's horizon)")
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
    p.add_argument("--cameras", default="",
                   help="record these cameras' images too, comma-separated (front, side, behind, wrist); default none")
    p.add_argument("--image-size", type=int, default=84, help="recorded image width and height [px] (default 84)")
    p.add_argument("--image-quality", default=DEFAULT_IMAGE_QUALITY, choices=IMAGE_QUALITIES, help=QUALITY_HELP)
    p.add_argument("--verbose", action="store_true", help="print how every attempt ended (default off)")
    for kind in KINDS:
        if kind.add_arguments is not None:
            kind.add_arguments(p.add_argument_group(f"--device {kind.name}"))


def run_collect(args: argparse.Namespace) -> int:
    import fetch  # noqa: F401  (registers the ids)
    from fetch.teleop import build

    # main() and collect_main() hold the stop handlers (fetch.stopping) around this.
    session = build.session_from_args(args)
    summary = session.run()
    print(summary.describe(), flush=True)
    if summary.exit_status == 0 and summary.total_saved:
        print(next_steps(args.out, args.format), flush=True)
    return summary.exit_status


def next_steps(out: str, dataset_format: str) -> str:
    """What to do with demos just collected into `out`: look at them, and learn from them."""
    if dataset_format != "hdf5":  # the npz files: what reads them
        return f"next: check them with `gym-fetch info {out}` and `gym-fetch replay {out} --check`"
    name = pathlib.PurePath(out).name or "demos"
    return (f"next: watch them with `gym-fetch view {out} --out report/{name}/`; train a policy on them with "
            f"`gym-fetch train {out} --out runs/{name}` (or first make many more from them: `gym-fetch generate`)")


def add_collect_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    c = sub.add_parser("collect", help="record demonstrations (gamepad, keyboard, scripted or expert)")
    add_collect_arguments(c)
    c.set_defaults(run=run_collect)


def collect_main(argv: Sequence[str] | None = None, prog: str = "collect_fetch_demo.py") -> int:
    """`gym-fetch collect` under another name (the original script): its usage and errors say `prog`."""
    p = argparse.ArgumentParser(prog=prog, description="Record demonstrations: the original collection script, "
                                "every flag with its meaning; the same as `gym-fetch collect`.")
    add_collect_arguments(p)
    p.set_defaults(run=run_collect, command="collect")
    return run_stoppable(lambda: p.parse_args(argv), prog)


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m fetch.collect ARGS`: `gym-fetch collect ARGS`."""
    from fetch.cli import main as cli_main

    return cli_main(["collect", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    raise SystemExit(main())
