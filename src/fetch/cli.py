"""`gym-fetch`: collect demonstrations, inspect, replay and convert datasets."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable, Sequence

from fetch._progress import StdoutError, guarded_stdout, stdout_gone

Command = Callable[[argparse.Namespace], int]


def add_collect_arguments(p: argparse.ArgumentParser) -> None:
    """The collector's flags: the seed script's (same names and meaning) plus ours."""
    from fetch.dataset.formats import FORMATS
    from fetch.learn import device as _  # noqa: F401  (registers --device policy, from the layer above teleop)
    from fetch.learn import takeover as _takeover  # noqa: F401  (registers --device takeover)
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
                   help="auto (default): a window when there is a display; rgb_array (the seed's) is headless "
                        "like none")
    p.add_argument("--device", default="gamepad", choices=DEVICE_NAMES,
                   help="what drives the arm (default gamepad): " + "; ".join(f"{k.name}: {k.summary}" for k in KINDS)
                        + ". Without a display or a pad: expert or scripted")
    p.add_argument("--format", default=FORMATS[0], choices=FORMATS,
                   help="hdf5 (default): robomimic's layout, replayable; npz: the seed's per-demo files")
    p.add_argument("--reward-type", default="sparse", choices=["sparse", "dense"],
                   help="sparse (default): -1 until the goal is reached, then 0; dense: minus the distance [m]")
    p.add_argument("--cameras", default="",
                   help="record these cameras' images too, comma-separated (front, side, behind, wrist); default none")
    p.add_argument("--image-size", type=int, default=84, help="recorded image width and height [px] (default 84)")
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
    return summary.exit_status


def run_info(args: argparse.Namespace) -> int:
    from fetch.dataset.recordings import open_recording

    with open_recording(args.file) as recording:
        print("\n".join(recording.summary()))
        problems = recording.problems()
    return _verdict(problems)


def _verdict(problems: list[str]) -> int:
    """Print `valid`, or the problems (the first 50); the exit status of `info`."""
    if problems:
        print(f"INVALID: {len(problems)} problem(s):")
        for p in problems[:50]:
            print(f"  - {p}")
        return 1
    print("valid")
    return 0


def run_render_obs(args: argparse.Namespace) -> int:
    from fetch.dataset.render_obs import describe, render_obs

    report = render_obs(args.file, args.camera, args.size, workers=args.workers, overwrite=args.overwrite)
    print(describe(report, args.camera, args.file))
    return 0


def run_merge(args: argparse.Namespace) -> int:
    from fetch.dataset.edit import merge

    report = merge(args.inputs, args.out, force=args.force)
    print(f"merged {len(args.inputs)} datasets: {report.demos} demos, {report.steps} steps -> {report.out} "
          "(" + ", ".join(f"{k} {v}" for k, v in sorted(report.masks.items())) + ")")
    return 0


def run_split(args: argparse.Namespace) -> int:
    from fetch.dataset.edit import split

    sizes = split(args.file, args.valid, args.seed)
    print(f"split {args.file}: " + ", ".join(f"{k} {v}" for k, v in sizes.items()))
    return 0


def _version() -> str:
    """`gym-fetch --version`: the package's, and the mujoco it runs on."""
    import mujoco

    import fetch

    return f"gym-fetch-v2 {fetch.__version__} (mujoco {mujoco.__version__}, python {sys.version.split()[0]})"


def _parser() -> argparse.ArgumentParser:
    from fetch.dataset.reader import FILE_HELP  # h5py, which export and view import here anyway
    from fetch.dataset.replay import add_replay_parser

    p = argparse.ArgumentParser(prog="gym-fetch", description=__doc__)
    p.add_argument("--version", action="version", version=_version())
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    c = sub.add_parser("collect", help="record demonstrations (gamepad, keyboard, scripted or expert)")
    add_collect_arguments(c)
    c.set_defaults(run=run_collect)
    i = sub.add_parser("info", help="summarise and validate a dataset; non-zero exit if it is inconsistent")
    i.add_argument("file", help=FILE_HELP)
    i.set_defaults(run=run_info)
    add_replay_parser(sub, FILE_HELP)
    o = sub.add_parser("render-obs", help="add a camera's images to every demo, rendered from the saved states")
    o.add_argument("file", help=FILE_HELP)
    o.add_argument("--camera", required=True, help="a camera of the env, e.g. front or wrist")
    o.add_argument("--size", type=int, default=84, help="image width and height [px] (default 84)")
    o.add_argument("--workers", type=int, default=None, help="render processes (default: one per core)")
    o.add_argument("--overwrite", action="store_true", help="render a camera the dataset already has again")
    o.set_defaults(run=run_render_obs)
    m = sub.add_parser("merge", help="combine datasets of the same env into one self-contained file")
    m.add_argument("inputs", nargs="+", metavar="FILE", help="datasets (files or collector directories), in order")
    m.add_argument("--out", required=True, help="the merged file (.hdf5)")
    m.add_argument("--force", action="store_true", help="replace --out if it exists")
    m.set_defaults(run=run_merge)
    s = sub.add_parser("split", help="remake mask/train and mask/valid from the successful demos")
    s.add_argument("file", help=FILE_HELP)
    s.add_argument("--valid", type=float, default=0.1, help="fraction of successful demos for validation (default 0.1)")
    s.add_argument("--seed", type=int, default=0, help="seed of the random assignment (default 0)")
    s.set_defaults(run=run_split)
    from fetch.dataset.exporters import add_export_parser  # minari is imported only when it runs
    from fetch.dataset.view import add_view_parser  # PyAV and the renderer are imported only when it runs
    from fetch.generate.cli import add_generate_parser  # the generator is imported only when it runs
    from fetch.learn.cli import add_learn_parsers  # torch is imported only when they run
    from fetch.teleop.gamepad import add_gamepad_parser  # pygame is imported only when it runs

    add_export_parser(sub)
    add_gamepad_parser(sub)
    add_learn_parsers(sub)
    add_view_parser(sub)
    add_generate_parser(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    # The parser is built inside: a Ctrl-C or SIGTERM while loading ends cleanly too.
    return _stoppable(lambda: _parser().parse_args(argv))


def collect_main(argv: Sequence[str] | None = None, prog: str = "collect_fetch_demo.py") -> int:
    """`gym-fetch collect` under another name (the seed's script): its usage and errors say `prog`."""
    p = argparse.ArgumentParser(prog=prog, description="Record demonstrations: the seed's collector, "
                                "every flag with its meaning; the same as `gym-fetch collect`.")
    add_collect_arguments(p)
    p.set_defaults(run=run_collect, command="collect")
    return _stoppable(lambda: p.parse_args(argv), prog)


def _stoppable(parse: Callable[[], argparse.Namespace], prog: str | None = None) -> int:
    """Parse the arguments and run the command with the stop handlers held (`fetch.stopping`): the exit
    status, 128 + the signal after a stop."""
    from fetch.stopping import stop_on_signals

    try:
        with stop_on_signals():
            return _run(parse(), prog)
    except KeyboardInterrupt as e:  # while parsing, or landed while the handlers were put back
        return _stopped(e)


def _stopped(e: KeyboardInterrupt) -> int:
    """The exit status after a stop signal: 128 + its number (Ctrl-C: 130, SIGTERM: 143)."""
    return 128 + int(getattr(e, "signum", signal.SIGINT))


def _run(args: argparse.Namespace, prog: str | None = None) -> int:
    from fetch.errors import FetchError

    try:
        with guarded_stdout():
            return int(args.run(args))
    except FetchError as e:
        print(f"{prog or 'gym-fetch ' + args.command}: error: {e}", file=sys.stderr)
        stop = _stop_behind(e)
        return 2 if stop is None else _stopped(stop)
    except KeyboardInterrupt as e:
        return _stopped(e)
    except OSError as e:  # what no tool turned into a FetchError: one line, not a traceback
        # A stop signal can break a pipe to a worker while the work is being wound down: that is
        # still the stop.
        stop = _stop_behind(e)
        if stop is not None:
            return _stopped(stop)
        if isinstance(e, BrokenPipeError):  # our stdout's reader went away (`| head`)
            stdout_gone()
            return 1
        name = prog or "gym-fetch " + args.command
        if isinstance(e, StdoutError):  # `> /dev/full`: the work is done, its report could not be written
            stdout_gone()
            print(f"{name}: error: cannot write to stdout ({e.strerror or e})", file=sys.stderr)
            return 1
        print(f"{name}: error: {e}", file=sys.stderr)
        return 2


def _stop_behind(e: BaseException) -> KeyboardInterrupt | None:
    """The stop signal (KeyboardInterrupt) that `e` was raised while handling, if any. (Python
    breaks any cycle when it sets `__context__`, so the chain ends.)"""
    context = e.__context__
    while context is not None and not isinstance(context, KeyboardInterrupt):
        context = context.__context__
    return context


if __name__ == "__main__":
    raise SystemExit(main())
