"""Benchmark the Fetch envs: step overhead over raw physics, make and reset speed, and gymnasium-robotics."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import io
import json
import os
import pickle
import statistics
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

import fetch
from benchmarks._machine import machine_table
from fetch.env import STATE_SPEC

OURS_COMPARED = "PickPlace-v2"
THEIRS = "FetchPickAndPlace-v4"
TARGET_RATIO = 1.10
TARGET_REMAKE_MS = 30.0
TARGET_RESETS_PER_S = 1000.0
TARGET_SPEEDUP = 1.3


# -- envs ------------------------------------------------------------------------------------------


def register_gymnasium_robotics() -> None:
    """Register gymnasium-robotics' ids, swallowing the version notice its import prints."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        import gymnasium_robotics

        gym.register_envs(gymnasium_robotics)


def is_theirs(env_id: str) -> bool:
    return env_id not in fetch.ENV_IDS


def fixed_actions(n: int, seed: int) -> list[np.ndarray]:
    """`n` reproducible uniform random actions in [-1, 1]^4 (float32, as action_space.sample())."""
    rng = np.random.default_rng(seed)
    return list(rng.uniform(-1.0, 1.0, size=(n, 4)).astype(np.float32))


def state_size(model: mujoco.MjModel) -> int:
    return int(mujoco.mj_stateSize(model, STATE_SPEC))


def get_state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    out = np.empty(state_size(model))
    mujoco.mj_getState(model, data, out, STATE_SPEC)
    return out


@dataclasses.dataclass
class Recording:
    """The MuJoCo states a rollout's `mj_step` calls started from (action already applied)."""

    pre_step: list[np.ndarray]
    n_substeps: int
    replay_max_diff: float
    """max |state after env.step - state after mj_step from the recorded state|: 0 means exact."""


def record_by_hook(env: gym.Env, actions: Sequence[np.ndarray], seed: int) -> Recording:
    """Capture each step's state at its first physics call (action applied) by wrapping mujoco.

    Works for both envs without re-implementing either: both call `mj_step(nstep)` (ours with the
    sensors off, then computes the positions and sensors the observation reads; mj_step1 and mj_step2
    are wrapped too, for an env that splits its last step). A replay checks that the recorded states
    are the env's own.
    """
    u: Any = env.unwrapped
    model = u.model
    scratch = mujoco.MjData(model)
    originals = {name: getattr(mujoco, name) for name in ("mj_step", "mj_step1", "mj_step2")}
    substeps = {"mj_step": None, "mj_step1": 0, "mj_step2": 1}
    state: list[np.ndarray] = []
    calls: list[tuple[str, int]] = []

    def hooked(name: str) -> Any:
        def call(m: mujoco.MjModel, d: mujoco.MjData, nstep: int = 1) -> None:
            if not calls:
                state.append(get_state(m, d))
            calls.append((name, nstep))
            if name == "mj_step":
                originals[name](m, d, nstep=nstep)
            else:
                originals[name](m, d)
        return call

    pre, worst, n_substeps = [], 0.0, 0
    env.reset(seed=seed)
    clone = pickle.loads(pickle.dumps(u)) if hasattr(u, "get_state") else None
    for name in originals:
        setattr(mujoco, name, hooked(name))
    try:
        for a in actions:
            state.clear()
            calls.clear()
            if hasattr(u, "get_state"):
                before = u.get_state()
            _, _, terminated, truncated, _ = env.step(a)
            if not calls:
                raise RuntimeError(f"{env.spec.id if env.spec else env}: no physics call in env.step")
            n_substeps = sum(n if substeps[name] is None else substeps[name] for name, n in calls)
            pre.append(state[0])
            if hasattr(u, "get_state"):
                # Ours: the step's first half-step ran before the action was applied, so check
                # against a copy of the env stepped from the state before the step.
                clone.set_state(before)
                clone.step(a)
                worst = max(worst, float(np.max(np.abs(u.get_state() - clone.get_state()))))
            else:
                # Theirs: one mj_step call; replay it from the captured state.
                mujoco.mj_setState(model, scratch, state[0], STATE_SPEC)
                for name, n in calls:
                    originals[name](model, scratch, nstep=n)
                worst = max(worst, float(np.max(np.abs(get_state(model, u.data) - get_state(model, scratch)))))
            if terminated or truncated:
                env.reset()
    finally:
        for name, original in originals.items():
            setattr(mujoco, name, original)
    return Recording(pre, n_substeps, worst)


# -- timing ----------------------------------------------------------------------------------------


def time_round(env: gym.Env, actions: Sequence[np.ndarray], rec: Recording, seed: int,
               scratch: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """[ns] per step of a seeded rollout: `env.step`, then `mj_step` alone from that step's recorded state.

    `actions` may be a prefix of the recorded rollout's.
    The two alternate step by step so that slow changes in the machine's load hit both alike.
    Physics runs on a scratch MjData of the same model, so the env's own data is left as the
    env left it; resets (at the TimeLimit) are not timed.
    """
    u: Any = env.unwrapped
    model, n = u.model, rec.n_substeps
    clock = time.perf_counter_ns
    step, mj_step, set_state = env.step, mujoco.mj_step, mujoco.mj_setState
    env_ns = np.empty(len(actions))
    physics_ns = np.empty(len(actions))
    env.reset(seed=seed)
    for k, (a, state) in enumerate(zip(actions, rec.pre_step[: len(actions)], strict=True)):
        t0 = clock()
        _, _, terminated, truncated, _ = step(a)
        t1 = clock()
        set_state(model, scratch, state, STATE_SPEC)
        t2 = clock()
        mj_step(model, scratch, nstep=n)
        t3 = clock()
        env_ns[k], physics_ns[k] = t1 - t0, t3 - t2
        if terminated or truncated:
            env.reset()
    return env_ns, physics_ns


def time_resets(env: gym.Env, n: int, seed: int) -> float:
    """[µs] mean wall time of `env.reset()` (after one seeded reset)."""
    clock = time.perf_counter_ns
    env.reset(seed=seed)
    t0 = clock()
    for _ in range(n):
        env.reset()
    return (clock() - t0) / n / 1e3


@dataclasses.dataclass
class Timings:
    """One env's times over all rounds: per round and step [ns], and per round for resets [µs]."""

    env_ns: list[np.ndarray] = dataclasses.field(default_factory=list)
    physics_ns: list[np.ndarray] = dataclasses.field(default_factory=list)
    reset_us: list[float] = dataclasses.field(default_factory=list)

    @property
    def step_us(self) -> float:
        """[µs] env.step: the mean over steps of each step's fastest round."""
        return float(np.min(self.env_ns, axis=0).mean()) / 1e3

    @property
    def physics_us(self) -> float:
        """[µs] mj_step alone: the mean over steps of each step's fastest round."""
        return float(np.min(self.physics_ns, axis=0).mean()) / 1e3

    def round_ratios(self) -> list[float]:
        """Each round's total env.step time over its total mj_step time."""
        return [float(e.sum() / p.sum()) for e, p in zip(self.env_ns, self.physics_ns, strict=True)]

    def round_step_us(self) -> list[float]:
        return [float(e.mean()) / 1e3 for e in self.env_ns]


@dataclasses.dataclass
class Subject:
    env_id: str
    env: gym.Env
    recording: Recording
    timings: Timings


def run_rounds(subjects: Sequence[Subject], actions: Sequence[np.ndarray], n_resets: int,
               n_rounds: int, seed: int, log: Callable[[str], None]) -> None:
    """Interleave: each round times every subject's steps with their physics, then its resets."""
    scratch = {s.env_id: mujoco.MjData(s.env.unwrapped.model) for s in subjects}  # type: ignore[attr-defined]
    for r in range(n_rounds):
        log(f"round {r + 1}/{n_rounds}")
        for s in subjects:
            env_ns, physics_ns = time_round(s.env, actions, s.recording, seed, scratch[s.env_id])
            s.timings.env_ns.append(env_ns)
            s.timings.physics_ns.append(physics_ns)
            s.timings.reset_us.append(time_resets(s.env, n_resets, seed))


# -- make time, in fresh processes -----------------------------------------------------------------


_PROBE = """
import contextlib, io, json, sys, time
env_id, repeats, theirs = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
t0 = time.perf_counter()
import gymnasium as gym
if theirs:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        import gymnasium_robotics
        gym.register_envs(gymnasium_robotics)
else:
    import fetch
import_ms = (time.perf_counter() - t0) * 1e3
t0 = time.perf_counter()
env = gym.make(env_id)
first_ms = (time.perf_counter() - t0) * 1e3
env.close()
again = []
for _ in range(repeats):
    t0 = time.perf_counter()
    env = gym.make(env_id)
    again.append((time.perf_counter() - t0) * 1e3)
    env.close()
print(json.dumps({"import_ms": import_ms, "first_ms": first_ms, "again_ms": again}))
"""
"""A fresh process: import (gymnasium and fetch, or gymnasium-robotics), the first `gym.make`
(compiles the scene), then `repeats` more makes of the same id; prints the times as JSON."""


@dataclasses.dataclass
class MakeTimes:
    first_ms: float
    """median over fresh processes of the first gym.make (scene compiled in it)."""
    again_ms: float
    """median of the later gym.make calls in those processes."""
    import_ms: float


def measure_make(env_id: str, processes: int, repeats: int) -> MakeTimes:
    results = []
    for _ in range(processes):
        command = [sys.executable, "-c", _PROBE, env_id, str(repeats), str(int(is_theirs(env_id)))]
        out = subprocess.run(command, capture_output=True, text=True)
        if out.returncode != 0:
            raise RuntimeError(f"make probe for {env_id} failed:\n{out.stderr}")
        results.append(json.loads(out.stdout.strip().splitlines()[-1]))
    return MakeTimes(
        first_ms=statistics.median(r["first_ms"] for r in results),
        again_ms=statistics.median(t for r in results for t in r["again_ms"]),
        import_ms=statistics.median(r["import_ms"] for r in results),
    )


def describe_error(exc: BaseException) -> str:
    last = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    where = f" at {os.path.basename(last.filename)}:{last.lineno} ({last.line})" if last else ""
    message = f": {exc}" if str(exc) else ""
    return f"{type(exc).__name__}{message}{where}".replace("\n", " ")


# -- report ----------------------------------------------------------------------------------------


def mark(ok: bool) -> str:
    return "yes" if ok else "no"


def target_line(what: str, met: Sequence[bool]) -> str:
    """One sentence under a table for a target its rows are held to, rather than a yes/no column."""
    return f"Target {what}: met by {sum(met)} of {len(met)} tasks."


def table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    align = ["---"] + ["---:"] * (len(head) - 1)
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def spread(values: Sequence[float], fmt: str = "{:.3f}") -> str:
    return f"{fmt.format(statistics.median(values))} ({fmt.format(min(values))}-{fmt.format(max(values))})"


def overhead_table(subjects: Sequence[Subject]) -> str:
    rows = []
    for s in subjects:
        t = s.timings
        step, phys = t.step_us, t.physics_us
        rows.append([s.env_id, f"{step:.0f}", f"{phys:.0f}", f"{step - phys:.0f}", f"{step / phys:.3f}",
                     spread(t.round_ratios()), f"{1e6 / step:.0f}", f"{s.recording.replay_max_diff:.1g}"])
    met = [s.timings.step_us / s.timings.physics_us <= TARGET_RATIO for s in subjects]
    return table(["task", "env.step µs", "mj_step µs", "overhead µs", "ratio",
                  "ratio per round: median (min-max)", "steps/s", "replay diff"], rows) + \
        f"\n\n{target_line(f'env.step / mj_step ≤ {TARGET_RATIO}', met)}"


def make_table(subjects: Sequence[Subject], makes: dict[str, MakeTimes]) -> str:
    rows = []
    for s in subjects:
        m = makes[s.env_id]
        per_round = [1e6 / us for us in s.timings.reset_us]
        rows.append([s.env_id, f"{m.first_ms:.0f}", f"{m.again_ms:.1f}", f"{max(per_round):.0f}",
                     f"{statistics.median(per_round):.0f}"])
    remade = [makes[s.env_id].again_ms <= TARGET_REMAKE_MS for s in subjects]
    reset = [1e6 / min(s.timings.reset_us) >= TARGET_RESETS_PER_S for s in subjects]
    return (table(["task", "first make ms", "make again ms", "resets/s (best round)", "resets/s (median round)"], rows)
            + f"\n\n{target_line(f'make again ≤ {TARGET_REMAKE_MS:.0f} ms', remade)} "
            + target_line(f"resets ≥ {TARGET_RESETS_PER_S:.0f}/s (best round)", reset))


def compare_table(ours: Subject, theirs: Subject, makes: dict[str, MakeTimes]) -> str:
    o, t = ours.timings, theirs.timings
    mo, mt = makes[ours.env_id], makes[theirs.env_id]
    step_speedups = [b / a for a, b in zip(o.round_step_us(), t.round_step_us(), strict=True)]
    reset_speedups = [b / a for a, b in zip(o.reset_us, t.reset_us, strict=True)]
    speed = t.step_us / o.step_us
    o_over, t_over = o.step_us - o.physics_us, t.step_us - t.physics_us
    rows = [
        ["first make ms", f"{mo.first_ms:.0f}", f"{mt.first_ms:.0f}", f"{mt.first_ms / mo.first_ms:.2f}x"],
        ["make again ms", f"{mo.again_ms:.1f}", f"{mt.again_ms:.1f}", f"{mt.again_ms / mo.again_ms:.2f}x"],
        ["env.step µs", f"{o.step_us:.0f}", f"{t.step_us:.0f}", f"{speed:.2f}x"],
        ["steps/s", f"{1e6 / o.step_us:.0f}", f"{1e6 / t.step_us:.0f}",
         f"{speed:.2f}x; per round {spread(step_speedups, '{:.2f}')}"],
        ["resets/s (best round)", f"{1e6 / min(o.reset_us):.0f}", f"{1e6 / min(t.reset_us):.0f}",
         f"{min(t.reset_us) / min(o.reset_us):.2f}x; per round {spread(reset_speedups, '{:.2f}')}"],
        ["mj_step µs (physics alone)", f"{o.physics_us:.0f}", f"{t.physics_us:.0f}",
         f"{t.physics_us / o.physics_us:.2f}x"],
        ["env.step / mj_step", f"{o.step_us / o.physics_us:.3f}", f"{t.step_us / t.physics_us:.3f}", ""],
        ["overhead µs (env.step - mj_step)", f"{o_over:.0f}", f"{t_over:.0f}", f"{t_over / o_over:.2f}x"],
    ]
    out = table(["", f"ours {ours.env_id}", f"gymnasium-robotics {theirs.env_id}", "ours faster by"], rows)
    return out + (f"\n\nStep speed ours/theirs: {speed:.2f}x; target ≥ {TARGET_SPEEDUP}x met: "
                  f"{mark(speed >= TARGET_SPEEDUP)}. Their replay diff: "
                  f"{theirs.recording.replay_max_diff:.1g}.")


# -- main ------------------------------------------------------------------------------------------


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--steps", type=int, default=200, help="env steps per rollout (default 200)")
    p.add_argument("--rounds", type=int, default=9, help="interleaved timing rounds (default 9)")
    p.add_argument("--resets", type=int, default=200, help="resets timed per round (default 200)")
    p.add_argument("--make-processes", type=int, default=3,
                   help="fresh processes per id for the make timing (default 3)")
    p.add_argument("--make-repeats", type=int, default=5,
                   help="gym.make calls after the first in each process (default 5)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--only", nargs="+", metavar="ID", choices=fetch.ENV_IDS,
                   help="benchmark only these of our ids")
    p.add_argument("--compare", action="store_true",
                   help=f"also compare {OURS_COMPARED} with gymnasium-robotics' {THEIRS}")
    return p.parse_args(argv)


def try_make_theirs() -> tuple[gym.Env | None, str]:
    try:
        register_gymnasium_robotics()
        return gym.make(THEIRS), ""
    except Exception as exc:  # noqa: BLE001 (reported, not hidden)
        return None, describe_error(exc)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)

    def log(msg: str) -> None:
        print(f"[bench] {msg}", file=sys.stderr, flush=True)

    ids = list(args.only or fetch.ENV_IDS)
    theirs_env, skipped = None, ""
    if args.compare:
        if OURS_COMPARED not in ids:
            ids.append(OURS_COMPARED)
        theirs_env, skipped = try_make_theirs()
        if theirs_env is None:
            skipped = (f"{THEIRS} could not be made on mujoco {mujoco.__version__} ({skipped}); "
                       "gymnasium-robotics' Fetch envs need mujoco < 3.12")
            log(f"comparison skipped: {skipped}")

    actions = fixed_actions(args.steps, args.seed)
    subjects: list[Subject] = []
    for env_id in ids:
        log(f"recording {env_id}")
        env = gym.make(env_id)
        subjects.append(Subject(env_id, env, record_by_hook(env, actions, args.seed), Timings()))
    theirs: Subject | None = None
    if theirs_env is not None:
        log(f"recording {THEIRS}")
        theirs = Subject(THEIRS, theirs_env, record_by_hook(theirs_env, actions, args.seed), Timings())

    everyone = subjects + ([theirs] if theirs else [])
    run_rounds(everyone, actions[:20], 20, 1, args.seed, log=lambda _: None)  # warm up
    for s in everyone:
        s.timings = Timings()
    gc.collect()
    run_rounds(everyone, actions, args.resets, args.rounds, args.seed, log)

    makes: dict[str, MakeTimes] = {}
    for s in everyone:
        log(f"make timing {s.env_id}")
        makes[s.env_id] = measure_make(s.env_id, args.make_processes, args.make_repeats)
    for s in everyone:
        s.env.close()

    print("## Machine and versions\n")
    print(machine_table("gymnasium-robotics"))
    print(f"\nSettings: {args.steps} steps per rollout (fixed random actions, seed {args.seed}; resets at "
          f"the TimeLimit not timed), {args.rounds} interleaved rounds, {args.resets} resets per round; "
          f"gym.make timed in {args.make_processes} fresh processes x (1 + {args.make_repeats}) makes.")
    print("\n## Step overhead: env.step vs mj_step alone\n")
    print(overhead_table(subjects))
    print("\n'env.step' is timed through the gym.make env (all its wrappers); 'mj_step' is "
          "`mj_step(model, data, nstep)` alone from the same pre-step states (action applied), on a "
          "scratch MjData, alternating step by step with env.step. Both are the mean over steps of "
          "each step's fastest round; 'ratio' = env.step / mj_step of those. 'ratio per round' is each "
          "round's total env.step / total mj_step. 'replay diff' = max |state| difference between "
          "env.step and mj_step from the recorded state (0: the recorded states are exactly the env's).")
    print("\n## gym.make and reset\n")
    print(make_table(subjects, makes))
    import_ms = statistics.median(makes[s.env_id].import_ms for s in subjects)
    print(f"\n'first make' is the median over fresh processes of the first gym.make of the id after "
          f"`import fetch` (it compiles and settles the scene); 'make again' is the median of the later "
          f"makes of the same id in those processes. `import fetch` itself: {import_ms:.0f} ms "
          f"(not included). Resets are `env.reset()` without a seed, best and median round.")
    if args.compare:
        print(f"\n## Comparison: {OURS_COMPARED} vs gymnasium-robotics {THEIRS}\n")
        if theirs is None:
            print(f"Comparison skipped: {skipped}.")
        else:
            ours = next(s for s in subjects if s.env_id == OURS_COMPARED)
            print(compare_table(ours, theirs, makes))
            print(f"\nSame method as above for both envs (their pre-step states are captured by "
                  f"wrapping `mujoco.mj_step`); their first make is after `import gymnasium_robotics` "
                  f"({makes[THEIRS].import_ms:.0f} ms, not included).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
