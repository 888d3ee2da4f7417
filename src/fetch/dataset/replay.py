"""Re-simulating saved demos: from their seed and from their saved states, compared bit for bit; and
`gym-fetch replay`, which does that or renders them to video."""

from __future__ import annotations

import argparse
import dataclasses
import math
import pathlib
from typing import Any

import gymnasium as gym
import numpy as np

from fetch.dataset.reader import FILE_HELP, Dataset


@dataclasses.dataclass(frozen=True)
class Deviation:
    """The largest difference found: its size and where."""

    value: float
    where: str


@dataclasses.dataclass(frozen=True)
class ReplayCheck:
    """How one demo's replay compares with what was recorded."""

    name: str
    steps: int
    reset: Deviation
    """`env.reset(seed)` vs the recorded first observation and `states[0]`."""
    observations: Deviation
    """Each step's observation vs `next_obs` (from the restored `states[0]`)."""
    states: Deviation
    """Each step's state vs `states[1:]`."""
    success_recorded: bool
    success_replayed: bool

    @property
    def exact(self) -> bool:
        return self.reset.value == 0 and self.observations.value == 0 and self.states.value == 0

    @property
    def largest(self) -> Deviation:
        return max((self.reset, self.observations, self.states), key=lambda d: d.value)


def make_replay_env(ds: Dataset) -> Any:
    """The dataset's env, unwrapped (no TimeLimit: demos may be longer than 50 steps)."""
    return gym.make(ds.env_id, **ds.env_kwargs).unwrapped


def other_model(ds: Dataset, env: Any) -> str | None:
    """Why a replay on `env` (from `make_replay_env`) need not be exact, or None when the dataset was
    recorded on this model: a line naming the two model hashes and the versions then and now. The
    physics of a task changes between releases (contacts, masses) and its MJB between MuJoCo
    versions, and a replay is bit for bit only on the model the demos were recorded on."""
    import mujoco

    import fetch

    recorded = str(ds.data_attrs.get("model_hash", ""))
    here = env.model_hash()
    if recorded in (here, env.legacy_model_hash()):
        return None
    then = ", ".join(f"{k} {ds.versions[k]}" for k in ("fetch", "mujoco") if k in ds.versions) or "versions unknown"
    return (f"note: {ds.path} was recorded on another model than this install's (model hash {recorded[:12]}, "
            f"here {here[:12]}; recorded with {then}, here fetch {fetch.__version__}, mujoco {mujoco.__version__}): "
            "a replay is exact only on the model it was recorded on, so a deviation here need not mean a damaged "
            "demo")


def largest_difference(replayed: np.ndarray, recorded: np.ndarray, label: str, row_offset: int = 0) -> Deviation:
    """The largest absolute difference (NaN counts as infinite) and its `label[row, column]`."""
    if replayed.size == 0:
        return Deviation(0.0, label)
    diff = np.abs(replayed - recorded)
    diff = np.where(np.isnan(diff), np.inf, diff)
    flat = int(np.argmax(diff))
    row, col = np.unravel_index(flat, diff.shape) if diff.ndim > 1 else (flat, 0)
    return Deviation(float(diff.flat[flat]), f"{label}[{int(row) + row_offset}, {int(col)}]")


def check_demo(ds: Dataset, name: str, env: Any | None = None) -> ReplayCheck:
    """Replay one demo: reset with its seed (compared with the start it recorded), restore
    `states[0]`, apply the recorded actions, compare every observation and state."""
    env = env if env is not None else make_replay_env(ds)
    group = ds.demo(name)
    keys = [k for k, _ in ds.layout.obs_sizes]
    return resimulate(name, env, int(group.attrs["seed"]), group["actions"][()], group["states"][()],
                      first={k: group[f"obs/{k}"][:1] for k in keys},
                      recorded_next={k: group[f"next_obs/{k}"][()] for k in keys},
                      success_recorded=bool(group["is_success"][()].any()))


def resimulate(name: str, env: Any, seed: int, actions: np.ndarray, states: np.ndarray,
               first: dict[str, np.ndarray], recorded_next: dict[str, np.ndarray],
               success_recorded: bool) -> ReplayCheck:
    """Reset `env` with `seed` (compared with `states[0]` and the `first` observation rows), restore
    `states[0]`, apply `actions`, compare every observation with `recorded_next` and every state
    with `states[1:]`. The one replay of both the HDF5 and the npz format."""
    keys = list(recorded_next)
    obs, _ = env.reset(seed=seed)
    start = env.get_state()
    reset_devs = [largest_difference(start[None], states[:1], "states")]
    reset_devs += [largest_difference(obs[k][None], first[k], f"obs/{k}") for k in keys if len(first[k])]
    reset = max(reset_devs, key=lambda d: d.value)

    env.set_state(states[0])
    replayed = {k: np.empty_like(recorded_next[k]) for k in keys}
    replayed_states = np.empty_like(states[1:])
    success = False
    for i, action in enumerate(actions):
        obs, _, _, _, info = env.step(action)
        for k in keys:
            replayed[k][i] = obs[k]
        env.get_state(out=replayed_states[i])
        success = success or info["is_success"] >= 1.0
    observations = max((largest_difference(replayed[k], recorded_next[k], f"next_obs/{k}") for k in keys),
                       key=lambda d: d.value, default=Deviation(0.0, "next_obs"))
    return ReplayCheck(name=name, steps=len(actions), reset=reset, observations=observations,
                       states=largest_difference(replayed_states, states[1:], "states", row_offset=1),
                       success_recorded=success_recorded, success_replayed=success)


def add_replay_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    r = sub.add_parser("replay", help="re-simulate demos and compare them with what was recorded, or render "
                                      "them to video")
    r.add_argument("file", help=FILE_HELP)
    r.add_argument("--demo", default=None, help="a demo index or name, e.g. 3 or demo_3 (default: all)")
    r.add_argument("--check", action="store_true",
                   help="compare observations and states bit for bit (what replay does without --video)")
    r.add_argument("--verbose", action="store_true", help="a line per demo, exact or not")
    r.add_argument("--video", default=None, metavar="OUT",
                   help="render the saved states to OUT (.mp4 or .gif), one frame per state; with several demos "
                        "one file each, named OUT_demo_<i>")
    r.add_argument("--camera", default="front", help="the video's camera: front (default), side, behind or wrist")
    r.add_argument("--size", type=int, default=480, help="video width and height [px] (default 480)")
    r.add_argument("--fps", type=float, default=None, help="frames per second (default: the control rate, 25)")
    r.set_defaults(run=run_replay)


def run_replay(args: argparse.Namespace) -> int:
    if args.video:
        status = run_video(args)
        if not args.check:
            return status
    return run_check(args)


def run_video(args: argparse.Namespace) -> int:
    from fetch._progress import progress
    from fetch.dataset.frames import StateRenderer
    from fetch.dataset.recordings import open_recording
    from fetch.dataset.video import check_video_path, write_video
    from fetch.errors import FetchError

    if args.fps is not None and not (math.isfinite(args.fps) and args.fps > 0):
        raise FetchError(f"--fps must be a positive number of frames per second, got {args.fps}")
    out = check_video_path(args.video, args.size, args.size)
    with open_recording(args.file, args.demo) as recording:
        recording.require_valid()
        with StateRenderer(recording.env_id, recording.env_kwargs, args.size, args.size) as renderer:
            renderer.check_camera(args.camera)
            fps = args.fps or 1.0 / renderer.env.dt
            for name in recording.names:
                path = out if len(recording.names) == 1 else out.with_name(f"{out.stem}_{name}{out.suffix}")
                states = recording.states(name)
                looks = renderer.looks(recording.seed(name))
                frames = (renderer.frame(state, args.camera, looks) for state in states)
                count = write_video(path, progress(frames, len(states), f"video {name}", unit="frames"), fps,
                                    args.size, args.size)
                print(f"{name}: {count} frames ({len(states) - 1} steps and the final state) at {fps:g} fps, "
                      f"camera {args.camera} -> {pathlib.Path(path)}")
    return 0


def run_check(args: argparse.Namespace) -> int:
    from fetch._progress import progress
    from fetch.dataset.recordings import open_recording

    with open_recording(args.file, args.demo) as recording:
        recording.require_valid()
        names = recording.names
        env = recording.replay_env()
        if note := recording.note(env):
            print(note)
        return _report(args, names, progress((recording.check(name, env) for name in names), len(names), "replay"),
                       env)


def _report(args: argparse.Namespace, names: list[str], checks: Any, env: Any) -> int:
    failures = 0
    largest: tuple[float, str] = (0.0, "")
    for r in checks:
        ok = r.exact and r.success_recorded == r.success_replayed
        failures += not ok
        dev = r.largest
        if dev.value >= largest[0]:
            largest = (dev.value, f"{r.name} {dev.where}")
        if not ok or args.verbose:
            success = "" if r.success_recorded == r.success_replayed else \
                f"; success recorded {r.success_recorded}, replayed {r.success_replayed}"
            verdict = "exact" if r.exact else f"DEVIATES; largest deviation {dev.value:.3g} at {dev.where}"
            print(f"{r.name}: {r.steps} steps, {verdict}{success}")
    env.close()
    print(f"replayed {len(names)} demo(s): {len(names) - failures} exact, {failures} deviating; largest "
          f"deviation {largest[0]:.3g}" + (f" ({largest[1]})" if largest[0] else ""))
    return 1 if failures else 0
