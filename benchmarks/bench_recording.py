"""Benchmark recording: overhead per env step, committing a 500-step demo, replay --check speed.

    python -m benchmarks.bench_recording [--env PickPlace-v2] [--steps 3000] [--existing 100]

Every figure is a ratio or a time measured in this one run (the machines are shared and noisy).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

import gymnasium as gym
import h5py
import numpy as np

from benchmarks._machine import machine_line
from fetch.dataset import open_dataset
from fetch.dataset.episode import EpisodeBuffer
from fetch.dataset.formats import open_writer, recorded_layout
from fetch.dataset.replay.check import check_demo, make_replay_env
from fetch.dataset.writer import DatasetWriter
from fetch.teleop.expert import ExpertDevice
from fetch.teleop.session import CollectConfig, Session, make_env

TARGET_OVERHEAD = 0.05
TARGET_COMMIT_MS = 50.0
TARGET_REPLAY = 0.80


def step_loop(env: gym.Env, actions: np.ndarray, record: EpisodeBuffer | None) -> float:
    """[s] per step of env.step (and, with a buffer, recording it as the collector does)."""
    base = env.unwrapped
    obs, _ = env.reset(seed=0)
    if record is not None:
        record.begin(obs, base.get_state())  # type: ignore[attr-defined]
    start = time.perf_counter()
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        if record is not None:
            base.get_state(out=record.state_row())  # type: ignore[attr-defined]
            record.record(a, obs, float(reward), terminated, truncated, info["is_success"] >= 1.0, time.time())
    return (time.perf_counter() - start) / len(actions)


def overhead(env_id: str, steps: int, repeats: int) -> tuple[float, float, float]:
    env = gym.make(env_id, max_episode_steps=steps + 1)
    buffer = EpisodeBuffer(recorded_layout(env), capacity=steps)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, 4)).astype(np.float32)
    plain, recorded = [], []
    for _ in range(repeats):  # interleaved, so drift in the machine's load hits both
        plain.append(step_loop(env, actions, None))
        recorded.append(step_loop(env, actions, buffer))
    p, r = statistics.median(plain), statistics.median(recorded)
    return p * 1e6, r * 1e6, r / p - 1.0


def commit_times(env_id: str, existing: int) -> tuple[float, float, float]:
    """[ms] the control loop's cost of committing a 500-step demo, and the writer thread's time to make it
    durable (demo file + index with `existing` demos), median over 10 commits."""
    env = make_env(CollectConfig(env_id=env_id, max_steps=600, stop_on_success=True))
    with tempfile.TemporaryDirectory() as out:
        config = CollectConfig(env_id=env_id, out=out, max_steps=600, device="expert", render="none",
                               keep_failures=True, stop_on_success=True)
        writer = open_writer("hdf5", out, env, settings=config.settings(), device="bench")
        assert isinstance(writer, DatasetWriter)
        buffer = EpisodeBuffer(recorded_layout(env), capacity=600)
        obs, _ = env.reset(seed=0)
        buffer.begin(obs, env.unwrapped.get_state())  # type: ignore[attr-defined]
        for _ in range(500):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            env.unwrapped.get_state(out=buffer.state_row())  # type: ignore[attr-defined]
            buffer.record(np.zeros(4, np.float32), obs, float(reward), terminated, truncated, False, time.time())
        attrs = {"seed": 0, "success": False, "env_id": env_id, "device": "bench", "attempt": 0,
                 "control_hz": 0.0, "achieved_hz": 0.0, "started": 0.0, "ended": 0.0}
        small = buffer.demo(attrs)
        small.arrays = {k: v[:5] for k, v in small.arrays.items()}
        small.arrays["states"] = buffer.states[:6].copy()
        small.attrs["num_samples"] = 5
        for _ in range(existing):
            writer.commit(small)
        writer.flush()
        loop, durable = [], []
        for _ in range(10):
            start = time.perf_counter()
            demo = buffer.demo(attrs)  # the copy the loop makes at the end of an attempt
            writer.commit(demo)
            queued = time.perf_counter()
            writer.flush()
            loop.append((queued - start) * 1e3)
            durable.append((time.perf_counter() - queued) * 1e3)
        writer.close()
    return statistics.median(loop), statistics.median(durable), max(durable)


def replay_speed(env_id: str, demos: int) -> tuple[float, float, float]:
    """Steps/s of `replay --check` and of plain env.step on the same demos' actions."""
    with tempfile.TemporaryDirectory() as out:
        config = CollectConfig(env_id=env_id, out=out, episodes=demos, device="expert", render="none",
                               stop_on_success=True, max_steps=500)  # as measured: each demo ends at success
        env = make_env(config)
        Session(config, ExpertDevice(env), env=env, log=lambda text: None).run()
        with open_dataset(out) as ds:
            replay_env = make_replay_env(ds)
            actions = [ds.demo(n)["actions"][()] for n in ds.demo_names]
            steps = sum(len(a) for a in actions)
            start = time.perf_counter()
            for name in ds.demo_names:
                assert check_demo(ds, name, replay_env).exact
            check = steps / (time.perf_counter() - start)
            start = time.perf_counter()
            for name, acts in zip(ds.demo_names, actions, strict=True):
                replay_env.reset(seed=int(ds.demo(name).attrs["seed"]))
                for a in acts:
                    replay_env.step(a)
            raw = steps / (time.perf_counter() - start)
    return check, raw, check / raw


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="PickPlace-v2")
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--existing", type=int, default=100, help="demos already in the dataset when committing")
    parser.add_argument("--demos", type=int, default=40, help="demos replayed")
    args = parser.parse_args()
    print(f"{machine_line('h5py')} (HDF5 {h5py.version.hdf5_version})\n")
    p, r, extra = overhead(args.env, args.steps, args.repeats)
    loop, durable, worst = commit_times(args.env, args.existing)
    check, raw, ratio = replay_speed(args.env, args.demos)
    rows = [
        ("env.step [us]", f"{p:.0f}", ""),
        ("env.step + recording [us]", f"{r:.0f}", ""),
        ("recording overhead", f"{100 * extra:.1f} %", f"< {100 * TARGET_OVERHEAD:.0f} %"),
        ("commit, control loop's share [ms]", f"{loop:.2f}", "never blocks"),
        (f"commit to durable, 500 steps, {args.existing} demos before [ms]", f"{durable:.1f} (max {worst:.1f})",
         f"< {TARGET_COMMIT_MS:.0f}"),
        ("replay --check [steps/s]", f"{check:.0f}", ""),
        ("raw env.step on the same actions [steps/s]", f"{raw:.0f}", ""),
        ("replay --check / raw", f"{ratio:.2f}", f">= {TARGET_REPLAY:.2f}"),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"| {'measure (' + args.env + ')':<{width}} | value | target |\n|{'-' * (width + 2)}|---|---|")
    for name, value, target in rows:
        print(f"| {name:<{width}} | {value} | {target} |")


if __name__ == "__main__":
    main()
