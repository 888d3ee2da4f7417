"""`gym-fetch generate`: many demos from a few, written in attempt order to an ordinary dataset.

The output directory is a collector's dataset (`gym-fetch info`, `replay --check`, `merge` and the
exports read it). `--demos` is the number it should hold: a run stopped by a kill continues, on the
same command, from the attempt after the last demo saved, and ends with the same demos an
uninterrupted run would have written.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
import sys
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from fetch._progress import Bar, bar_text
from fetch.camera_obs import DEFAULT_IMAGE_SIZE, check_cameras
from fetch.dataset import schema
from fetch.dataset.dirs import require_apart
from fetch.dataset.formats import open_writer
from fetch.dataset.reader import open_dataset
from fetch.errors import FetchError
from fetch.generate.attempt import Options, Result, task_hand_response
from fetch.generate.room import NO_TIGHT_START
from fetch.generate.sources import Sources, load_sources
from fetch.generate.workers import Backend, Pool, RayCluster, Serial, Work, default_workers
from fetch.looks import check_looks
from fetch.rendering import DEFAULT_IMAGE_QUALITY, check_camera_list, check_image_quality, check_image_size

MAX_SEED = 2**62
LOW_YIELD = (200, 0.05)
"""After this many attempts, a success rate below this fraction is worth a word (Slide's strikes: 1.7 %)."""


@dataclasses.dataclass(frozen=True)
class GenerateConfig:
    """A generation run's settings (the `gym-fetch generate` flags)."""

    source: str
    out: str
    demos: int
    seed: int = 0
    workers: int | None = None
    """None: one per core (or, with Ray, per CPU of the cluster)."""
    options: Options | None = None
    """None: the defaults, with max_steps the env's registered horizon."""
    max_attempts: int | None = None
    """give up after this many attempts in all (None: 50 per demo asked for)."""
    ray: str | None = None
    """None: no Ray; "local": start a Ray instance here; else a cluster's address ("auto", "ray://...")."""
    nice: int = 0
    """niceness of the worker processes (not Ray's)."""
    cameras: tuple[str, ...] = ()
    """record these cameras' images too (`obs/<camera>_image`, `next_obs/...`), rendered in the workers."""
    image_size: int = DEFAULT_IMAGE_SIZE
    """[px] the images' width and height."""
    image_quality: str = DEFAULT_IMAGE_QUALITY
    """how the images are drawn (`rendering.IMAGE_QUALITIES`)."""
    looks: str | None = None
    """the demos' looks (`fetch.looks.LOOKS`; "random": each demo's drawn from its reset seed, recorded in the
    dataset's env kwargs); None: the source dataset's."""

    def __post_init__(self) -> None:
        if self.demos < 1:
            raise FetchError(f"--demos must be at least 1, got {self.demos}")
        if not 0 <= self.seed <= MAX_SEED:
            raise FetchError(f"--seed must be a whole number from 0 to 2**62, got {self.seed}")
        if self.workers is not None and self.workers < 1:
            raise FetchError(f"--workers must be at least 1, got {self.workers}")
        if self.max_attempts is not None and self.max_attempts < 1:
            raise FetchError(f"--max-attempts must be at least 1, got {self.max_attempts}")
        if not str(self.out).strip():
            raise FetchError("--out must name a directory (it is empty)")
        if isinstance(self.cameras, str):
            raise FetchError(f"cameras must be a sequence of camera names, e.g. cameras=({self.cameras!r},)")
        check_image_size(self.image_size, "--image-size")  # as collect's: checked with no cameras too
        check_image_quality(self.image_quality, "--image-quality")
        check_camera_list(self.cameras)
        if self.looks is not None:
            check_looks(self.looks, "--looks")


@dataclasses.dataclass
class Summary:
    saved: int
    """demos saved by this run."""
    total: int
    """demos in the dataset now."""
    attempts: int
    """attempts made by this run."""
    successes: int
    seconds: float
    workers: int
    out: str
    gave_up: bool = False
    startup: float = 0.0
    """[s] until the first attempt's result came back (starting workers, building their envs)."""
    skipped: int = 0
    """starts passed over without an attempt (`Options.starts`)."""

    @property
    def success_rate(self) -> float:
        return self.successes / self.attempts if self.attempts else 0.0

    def describe(self) -> str:
        rate = 60 * self.saved / self.seconds if self.seconds > 0 else 0.0
        text = (f"{self.attempts} attempts, {self.saved} saved this run ({self.total} in {self.out}), success rate "
                f"{100 * self.success_rate:.0f}%, {rate:.0f} demos/min on {self.workers} worker(s)")
        if self.skipped:
            text += f"; {self.skipped} starts that were not tight skipped"
        return text + ("\ngave up: --max-attempts reached" if self.gave_up else "")


def settings_of(sources: Sources, options: Options, seed: int) -> dict[str, Any]:
    """What the dataset records as made it; a resumed run must match every field. `retries` 0, `fit_opening` and
    `steady_fit` off, `starts` "all", `hand_response` 1 and a `finger_noise` equal to `noise` are left out, so that
    a dataset generated before they existed resumes with `--retries 0 --no-fit-opening --no-steady-fit
    --finger-noise <its noise>`."""
    recorded = dataclasses.asdict(options)
    recorded["finger_noise"] = options.finger_std
    if options.finger_std == options.noise:
        del recorded["finger_noise"]
    for name in ("retries", "fit_opening", "steady_fit"):
        if not recorded[name]:
            del recorded[name]
    if recorded["starts"] == "all":
        del recorded["starts"]
    if recorded["hand_response"] == 1:
        del recorded["hand_response"]
    return {"max_steps": options.max_steps, "success_hold_steps": options.success_hold_steps,
            "stop_on_success": options.stop_on_success, "ignore_env_done": False,
            "generate": {"source": sources.path, "source_fingerprint": sources.fingerprint,
                         "source_demos": len(sources.segments), "subtasks": list(sources.subtasks), "seed": seed,
                         **recorded}}


def _resume_point(out: str) -> tuple[int, int | None]:
    """(demos in the dataset, the attempt number of its last demo)."""
    with open_dataset(out) as ds:
        if not ds.demo_names:
            return 0, None
        return len(ds.demo_names), max(int(ds.attrs(n)["attempt"]) for n in ds.demo_names)


def _images(cameras: tuple[str, ...], size: int, quality: str) -> str:
    return f"--cameras {','.join(cameras)} --image-size {size} --image-quality {quality}" if cameras else "no --cameras"


def require_same_images(out: str, cameras: tuple[str, ...], size: int, quality: str) -> None:
    """One line naming both when `out` holds a dataset recorded with other cameras, another image size or
    quality (the writer refuses every difference, this one among them, but in several lines)."""
    if not (pathlib.Path(out) / schema.INDEX_NAME).is_file():
        return
    with open_dataset(out) as ds:
        layout = ds.layout
    had = (layout.cameras, layout.image_size, layout.image_quality) if layout.cameras else ((), 0, "")
    if had != ((cameras, size, quality) if cameras else ((), 0, "")):
        raise FetchError(f"{out} holds demos with {_images(*had)}, this run asks for "
                         f"{_images(cameras, size, quality)}; use the same, or another --out")


def make_backend(config: GenerateConfig, work: Work) -> Backend:
    if config.ray is not None:
        return RayCluster(work, None if config.ray == "local" else config.ray, config.workers)
    workers = config.workers or default_workers()
    return Serial(work) if workers == 1 else Pool(work, workers, config.nice)


def generate(config: GenerateConfig, log: Callable[[str], None] | None = None) -> Summary:
    """Generate until `--out` holds `config.demos` demos (or the attempts run out)."""
    say = log or (lambda text: print(text, file=sys.stderr, flush=True))
    require_apart(config.out, [config.source])
    sources = load_sources(config.source)
    if config.looks is not None and config.looks != sources.env_kwargs.get("looks", "plain"):
        sources = dataclasses.replace(sources, env_kwargs={**sources.env_kwargs, "looks": config.looks})
    options = config.options or Options()
    if options.max_steps is None:
        options = dataclasses.replace(options, max_steps=sources.attempt_steps(options.success_hold_steps))
    if options.hand_response is None:
        options = dataclasses.replace(options, hand_response=task_hand_response(sources.env_id))
    if sources.skipped:
        say(f"{len(sources.skipped)} source demo(s) could not be cut into {', '.join(sources.subtasks)} "
            f"and are not used: {', '.join(sources.skipped[:5])}")
    env = gym.make(sources.env_id, max_episode_steps=options.max_steps, **sources.env_kwargs)
    try:
        base: Any = env.unwrapped
        cameras = check_cameras(base.model, config.cameras, config.image_size)
        require_same_images(config.out, cameras, config.image_size, config.image_quality)
        writer = open_writer("hdf5", config.out, env, settings=settings_of(sources, options, config.seed),
                             device="generate", cameras=cameras, image_size=config.image_size,
                             image_quality=config.image_quality)
    finally:
        env.close()
    try:
        have, last = _resume_point(config.out)
        first = 0 if last is None else last + 1
        writer.attempts = first
        summary = Summary(0, have, 0, 0, 0.0, 1, config.out)
        if have >= config.demos:
            return summary
        limit = config.max_attempts or 50 * config.demos
        backend = make_backend(config, Work(sources, options, config.seed, cameras, config.image_size,
                                                   config.image_quality))
        summary.workers = backend.workers
        started = time.perf_counter()
        bar = _Bar(config.demos)
        previous = last
        made = 0 if last is None else None  # attempts since the previous demo (None: unknown, across a resume)
        try:
            for result in backend.results(first):
                writer.reserve_attempt()
                if not result.made:
                    summary.skipped += 1
                    if summary.skipped >= NO_TIGHT_START and not summary.attempts:
                        raise FetchError(f"none of {NO_TIGHT_START} starts of {sources.env_id} is tight (its object "
                                         "close beside something along the fingers' axis): --starts tight makes "
                                         "nothing on this task; use --starts all")
                    continue
                if not summary.attempts:
                    summary.startup = time.perf_counter() - started
                summary.attempts += 1
                if made is not None:
                    made += 1
                if result.demo is not None:
                    _commit(writer, result, previous, made)
                    previous, made = result.number, 0
                    summary.successes += 1
                    summary.saved += 1
                    summary.total += 1
                bar.show(summary, time.perf_counter() - started)
                if summary.attempts == LOW_YIELD[0]:
                    note = low_yield(summary, config.demos, limit, time.perf_counter() - started)
                    if note:
                        bar.end()
                        say(note)
                if summary.total >= config.demos:
                    break
                if summary.attempts >= limit:
                    summary.gave_up = True
                    break
        finally:
            summary.seconds = time.perf_counter() - started
            bar.end()
            backend.close()
    finally:
        writer.close()
    return summary


def _commit(writer: Any, result: Result, previous: int | None, made: int | None) -> None:
    """Save `result`'s demo; `made`: attempts since the previous demo, this one included (None: count the attempt
    numbers since `previous`, skipped starts included, as across a resume)."""
    demo = result.demo
    assert demo is not None
    demo.attrs.update(
        source_demos=json.dumps([c[0] for c in result.choices]),
        source_segments=json.dumps([[c[1], c[2]] for c in result.choices]),
        source_subtasks=json.dumps([c[3] for c in result.choices]),
        segment_starts=json.dumps(list(result.starts)),
        generation_attempts=made if made is not None else result.number - (-1 if previous is None else previous))
    for camera, frames in result.images.items():  # rendered in the worker: the writer renders none
        key = schema.image_key(camera)
        demo.arrays[f"obs/{key}"], demo.arrays[f"next_obs/{key}"] = frames[:-1], frames[1:]
    writer.commit(demo)


def low_yield(summary: Summary, wanted: int, limit: int, seconds: float) -> str | None:
    """What to say when few attempts succeed (`LOW_YIELD`): how long the rest will take at this rate,
    whether the attempt limit comes first, and why it may be so; None when the rate is fine."""
    attempts, rate = summary.attempts, summary.success_rate
    if attempts < LOW_YIELD[0] or rate >= LOW_YIELD[1]:
        return None
    left = wanted - summary.total
    needed = left / rate if rate > 0 else float("inf")
    if needed > limit - attempts:
        outlook = (f"at this rate --max-attempts ({limit}) runs out with about "
                   f"{summary.total + int(rate * (limit - attempts))} of the {wanted} demos")
    else:
        outlook = f"at this rate the other {left} demos take ~{needed * seconds / attempts / 60:.0f} min"
    return (f"only {summary.successes} of {attempts} attempts succeeded ({100 * rate:.1f} %): {outlook}. "
            "The sources' motions may not carry over to new object and goal poses (Slide's strikes do not: "
            "docs/generate.md); more source demos, or recording the demos directly, may serve better.")


class _Bar:
    """Generation's progress line (`fetch._progress.Bar`): demos, attempts, running success rate, rate."""

    def __init__(self, target: int) -> None:
        self.target = target
        self.bar = Bar()

    def show(self, s: Summary, elapsed: float) -> None:
        rate = 60 * s.saved / elapsed if elapsed > 0 else 0.0
        self.bar.show(bar_text("generate", s.total, self.target, f"demos, {s.attempts} attempts, success "
                               f"{100 * s.success_rate:.0f}%, {rate:.0f}/min "), last=s.total >= self.target)

    def end(self) -> None:
        self.bar.end()
