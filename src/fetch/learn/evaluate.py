"""Evaluating a policy: many episodes at once on seeds the dataset never used; success with its 95 % interval."""

from __future__ import annotations

import dataclasses
import math
import pathlib
from collections.abc import Callable, Iterable
from typing import Any

import gymnasium as gym
import numpy as np

from fetch.errors import FetchError
from fetch.tasks import registered_horizon

EVAL_SEED_START = 1_000_000
"""Evaluation seeds count up from here, skipping any seed of the dataset (collections start at 0)."""


def make_vector_env(env_id: str, count: int, env_kwargs: dict[str, Any],
                    max_episode_steps: int | None = None) -> gym.vector.VectorEnv:
    """`count` copies of the env stepped as one batch, the one place evaluation builds its envs:
    `fetch.make_vec` (every world in this process, stepped on all cores' C threads) where mujoco has
    `mujoco.batch` (4.0 on); on older mujoco it could only step its worlds one after another, and
    Gymnasium's `SyncVectorEnv` does the same without the warning. Either gives the results a single
    env would, bit for bit, so the choice changes only the speed."""
    import fetch
    from fetch.vector import has_batch

    kwargs = dict(env_kwargs)
    if max_episode_steps is not None:
        kwargs["max_episode_steps"] = max_episode_steps
    if has_batch() and count > 1:
        return fetch.make_vec(env_id, count, **kwargs)
    return gym.vector.SyncVectorEnv([lambda: gym.make(env_id, **kwargs) for _ in range(count)])


def eval_seeds(count: int, exclude: Iterable[int], start: int = EVAL_SEED_START) -> list[int]:
    """`count` reset seeds from `start` up, none of them in `exclude` (the dataset's)."""
    used = set(exclude)
    seeds: list[int] = []
    seed = start
    while len(seeds) < count:
        if seed not in used:
            seeds.append(seed)
        seed += 1
    return seeds


def wilson(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """The Wilson score interval of a success rate (95 % for the default z); (0, 1) when n is 0."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclasses.dataclass(frozen=True)
class EvalResult:
    """Per-episode outcomes: success at the last step of the policy's horizon, success at the last step
    of the task's registered horizon (the standard Fetch rate; the same when the two agree), success at
    any step, and the first successful step (the horizon when never)."""

    env_id: str
    seeds: tuple[int, ...]
    success: tuple[bool, ...]
    ever: tuple[bool, ...]
    first_success: tuple[int, ...]
    horizon: int
    registered: int
    """[steps] the task's registered horizon."""
    registered_success: tuple[bool, ...]

    @property
    def registered_rate(self) -> float:
        return sum(self.registered_success) / max(1, self.episodes)

    @property
    def episodes(self) -> int:
        return len(self.seeds)

    @property
    def rate(self) -> float:
        return sum(self.success) / max(1, self.episodes)

    @property
    def interval(self) -> tuple[float, float]:
        return wilson(sum(self.success), self.episodes)

    @property
    def mean_length(self) -> float:
        """[steps] mean episode length, an episode ending at its first success."""
        return float(np.mean(self.first_success)) if self.first_success else 0.0

    def describe(self) -> str:
        lo, hi = self.interval
        registered = ""
        if self.registered != self.horizon:
            rlo, rhi = wilson(sum(self.registered_success), self.episodes)
            registered = (f" (the policy's horizon, from its demos); at the registered step {self.registered}: "
                          f"{100 * self.registered_rate:.1f}% (95% CI {100 * rlo:.1f}-{100 * rhi:.1f}%)")
        return (f"{self.env_id}: success {100 * self.rate:.1f}% ({sum(self.success)}/{self.episodes}, 95% CI "
                f"{100 * lo:.1f}-{100 * hi:.1f}%) at step {self.horizon}{registered}; succeeded at some step "
                f"{100 * sum(self.ever) / max(1, self.episodes):.1f}%; mean episode length {self.mean_length:.1f} "
                f"steps (to first success, {self.horizon} if never); seeds {self.seeds[0]}..{self.seeds[-1]} "
                "(none from the dataset)")

    def as_dict(self) -> dict[str, Any]:
        lo, hi = self.interval
        return {"env_id": self.env_id, "episodes": self.episodes, "success_rate": self.rate, "ci95": [lo, hi],
                "ever_success_rate": sum(self.ever) / max(1, self.episodes), "mean_length": self.mean_length,
                "horizon": self.horizon, "registered_horizon": self.registered,
                "registered_success_rate": self.registered_rate, "seeds": list(self.seeds),
                "success": list(self.success), "ever": list(self.ever)}


def evaluate(policy: Any, episodes: int, *, envs: int = 50, seed_start: int = EVAL_SEED_START,
             on_wave: Callable[[int], None] | None = None) -> EvalResult:
    """Run `policy` (a `Policy`) for `episodes` episodes of its horizon (`policy.horizon`, at least the
    task's registered one), `envs` at a time, on seeds disjoint from its dataset's."""
    if episodes < 1:
        raise FetchError(f"--episodes must be a whole number >= 1, got {episodes}")
    if envs < 1:
        raise FetchError(f"--envs must be a whole number >= 1, got {envs}")
    registered = registered_horizon(policy.env_id)
    horizon = max(registered, int(getattr(policy, "horizon", registered)))
    seeds = eval_seeds(episodes, policy.seeds, seed_start)
    count = min(envs, episodes)
    success: list[bool] = []
    at_registered: list[bool] = []
    ever: list[bool] = []
    first: list[int] = []
    vec = make_vector_env(policy.env_id, count, {**policy.env_kwargs, **getattr(policy, "observation_kwargs", {})},
                          horizon)
    try:
        for wave in range(0, episodes, count):
            wave_seeds = seeds[wave:wave + count]
            # The last wave may be short: its spare envs run on further unused seeds and are not counted.
            padded = wave_seeds + eval_seeds(count - len(wave_seeds), set(policy.seeds) | set(seeds),
                                             seeds[-1] + 1)
            obs, _ = vec.reset(seed=padded)  # type: ignore[arg-type]  # a list: one seed per env
            policy.reset()
            reached = np.full(count, horizon)
            last = np.zeros(count, bool)
            registered_last = last
            for t in range(horizon):
                obs, _, _, _, info = vec.step(policy(obs))
                last = np.asarray(info["is_success"], float) > 0
                reached = np.where(last & (reached == horizon), t + 1, reached)
                if t + 1 == registered:
                    registered_last = last
            n = len(wave_seeds)
            success += [bool(s) for s in last[:n]]
            at_registered += [bool(s) for s in registered_last[:n]]
            ever += [bool(r < horizon or s) for r, s in zip(reached[:n], last[:n], strict=True)]
            first += [int(r) for r in reached[:n]]
            if on_wave is not None:
                on_wave(len(success))
    finally:
        vec.close()
    return EvalResult(policy.env_id, tuple(seeds), tuple(success), tuple(ever), tuple(first), horizon, registered,
                      tuple(at_registered))


def record_videos(policy: Any, seeds: list[int], out_dir: str | pathlib.Path, *, camera: str = "front",
                  size: int = 320) -> list[pathlib.Path]:
    """One mp4 per seed in `out_dir` (`<env>_seed<seed>.mp4`) of the policy acting for the horizon."""
    from fetch.dataset.render.video import check_video_path, write_video

    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    env: Any = gym.make(policy.env_id, render_mode="rgb_array", width=size, height=size, camera_name=camera,
                        **policy.env_kwargs, **getattr(policy, "observation_kwargs", {}))
    try:
        horizon = int(getattr(policy, "horizon", None) or (env.spec.max_episode_steps if env.spec else 50) or 50)
        for seed in seeds:
            path = check_video_path(out / f"{policy.env_id}_seed{seed}.mp4", size, size)
            obs, _ = env.reset(seed=seed)
            policy.reset()
            frames = [env.render()]
            for _ in range(horizon):
                obs, *_ = env.step(policy(obs))
                frames.append(env.render())
            fps = 1.0 / float(env.unwrapped.dt)
            write_video(path, frames, fps, size, size)
            written.append(path)
    finally:
        env.close()
    return written
