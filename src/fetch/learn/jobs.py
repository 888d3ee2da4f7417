"""What `gym-fetch train` and `gym-fetch eval` run, each a function of one typed request, for the CLI and
Python callers alike (torch is imported only when they run)."""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
from collections.abc import Callable

from fetch._progress import said_if_slow
from fetch.errors import FetchError
from fetch.learn import require_torch
from fetch.learn.settings import CORRECTION_WEIGHT, TrainRequest, sees_pixels


@dataclasses.dataclass(frozen=True)
class TrainJob:
    """A training run on datasets (`gym-fetch train`): what to learn from, where the run goes, and the
    `TrainRequest` saying what to train (its None fields left to `settings.plan`)."""

    datasets: tuple[str, ...]
    """dataset directories or files of one task, learnt from together."""
    out: str | os.PathLike[str]
    """the run directory (resumed when it holds the same run)."""
    request: TrainRequest = TrainRequest()
    correction_weight: int = CORRECTION_WEIGHT
    """how many times each stretch a person drove in a corrected attempt counts among the training demos."""


def train_datasets(job: TrainJob) -> str:
    """Train the run `job` asks for; returns the line that reports it (what was trained, the losses, how to
    evaluate it)."""
    require_torch()
    from fetch.learn import checkpoint
    from fetch.learn.data import load_many
    from fetch.learn.train import train

    request = job.request
    base = checkpoint.read(request.start_from) if request.start_from is not None else None
    with said_if_slow(f"reading {', '.join(job.datasets)} ..."):
        demos = load_many(list(job.datasets), job.correction_weight, images=sees_pixels(request, base))
    result = train(demos, job.out, request)
    policy, config = result.plan.policy, result.plan.config
    valid = "none (no valid split)" if result.valid_loss is None else f"{result.valid_loss:.4f}"
    resumed = f", resumed at step {result.resumed_from}" if result.resumed_from else ""
    members = f" ({policy.members} members)" if policy.members > 1 else ""
    mirrored = " and their mirror images" if config.mirror else ""
    mirrored += f", seeing {', '.join(policy.cameras)}" if policy.cameras else ""
    mirrored += ", not seeing velocities" if policy.blind and not policy.cameras else ""
    return (f"trained {policy.kind}{members} on {len(demos.train[:config.demos or None])} {demos.env_id} demos"
            f"{mirrored} for {result.steps} steps{resumed}: train loss {result.train_loss:.4f}, valid loss {valid}; "
            f"evaluate with: gym-fetch eval {job.out}")


@dataclasses.dataclass(frozen=True)
class EvalRequest:
    """An evaluation of a trained run (`gym-fetch eval`), on seeds its dataset never used."""

    run_dir: str | os.PathLike[str]
    episodes: int = 100
    envs: int = 50
    """episodes stepped at once."""
    seed_start: int | None = None
    """the first evaluation seed (None: `fetch.learn.evaluate.EVAL_SEED_START`)."""
    video: str | pathlib.Path | None = None
    """a directory for mp4s of the first `videos` episodes (None: none)."""
    videos: int = 3
    camera: str = "front"
    """the videos' camera."""
    json: str | os.PathLike[str] | None = None
    """a file for the per-episode results as JSON (None: none)."""
    looks: str | None = None
    """the scene's looks (`fetch.looks.LOOKS`; None: those of the policy's training data)."""
    act_steps: int | None = None
    """a chunk policy predicts every this many steps (`Policy.act_every`; None: as its run says)."""


def evaluate_run(request: EvalRequest, say: Callable[[str], object] = print) -> None:
    """Run `request`'s policy on its episodes; `say` each report line (the results, then the videos written)
    as it is ready."""
    require_torch()
    from fetch.learn.evaluate import EVAL_SEED_START, evaluate, record_videos
    from fetch.learn.runtime import load

    seed_start = EVAL_SEED_START if request.seed_start is None else request.seed_start
    if seed_start < 0:
        raise FetchError(f"--seed-start must be a whole number >= 0, got {seed_start}")
    if request.video is not None and request.videos < 1:
        raise FetchError(f"--videos must be a whole number >= 1, got {request.videos}")
    if request.video is not None:
        from fetch.dataset.render.video import require_pyav

        require_pyav()  # before the episodes, not after them
    policy = load(request.run_dir)
    if request.act_steps is not None:
        policy.act_every(request.act_steps)
    if request.looks is not None:
        policy.env_kwargs = {**policy.env_kwargs, "looks": request.looks}
    if request.video is not None:
        from fetch.dataset.render.frames import check_env_camera

        check_env_camera(policy.env_id, policy.env_kwargs, request.camera)
    result = evaluate(policy, request.episodes, envs=request.envs, seed_start=seed_start)
    say(result.describe())
    if request.json is not None:
        acting = {} if request.act_steps is None else {"act_steps": request.act_steps}  # not the run's own
        pathlib.Path(request.json).write_text(json.dumps(result.as_dict() | acting, indent=1))
    if request.video is not None:
        written = record_videos(policy, list(result.seeds[:request.videos]), request.video, camera=request.camera)
        say(f"videos: {', '.join(str(p) for p in written)}")
