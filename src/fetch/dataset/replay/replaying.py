"""`gym-fetch replay`'s work: re-simulate a recording's demos and compare them with what was recorded
(`replay/check.py`), or render their saved states to video (`replay`, with a `ReplayRequest`)."""

from __future__ import annotations

import dataclasses
import math
import pathlib
from typing import Any

from fetch.dataset.replay.recordings import open_recording


@dataclasses.dataclass(frozen=True)
class ReplayRequest:
    """What to replay, and how."""

    file: str
    """the recording (a dataset directory or file, or npz files)."""
    demo: str | None = None
    """a demo index or name (None: all)."""
    check: bool = False
    """compare bit for bit even with `video` (without it, that is what a replay does)."""
    verbose: bool = False
    """a line per demo, exact or not."""
    video: str | None = None
    """render the saved states to this file (.mp4 or .gif); with several demos one file each, `<stem>_<demo>`."""
    camera: str = "front"
    """the video's camera."""
    size: int = 480
    """the video's width and height [px]."""
    fps: float | None = None
    """the video's frames per second (None: the control rate)."""


def replay(request: ReplayRequest) -> int:
    """Render the video `request` asks for, then (without a video, or with `check`) replay the demos and print
    how each compares; the exit status: 1 if a demo deviates, else 0."""
    if request.video:
        status = _video(request)
        if not request.check:
            return status
    return _check(request)


def _video(request: ReplayRequest) -> int:
    from fetch._progress import progress
    from fetch.dataset.render.frames import StateRenderer
    from fetch.dataset.render.video import check_video_path, write_video
    from fetch.errors import FetchError

    assert request.video is not None
    if request.fps is not None and not (math.isfinite(request.fps) and request.fps > 0):
        raise FetchError(f"--fps must be a positive number of frames per second, got {request.fps}")
    out = check_video_path(request.video, request.size, request.size)
    with open_recording(request.file, request.demo) as recording:
        recording.require_valid()
        with StateRenderer(recording.env_id, recording.env_kwargs, request.size, request.size) as renderer:
            renderer.check_camera(request.camera)
            fps = request.fps or 1.0 / renderer.env.dt
            for name in recording.names:
                path = out if len(recording.names) == 1 else out.with_name(f"{out.stem}_{name}{out.suffix}")
                states = recording.states(name)
                looks = renderer.looks(recording.seed(name))
                frames = (renderer.frame(state, request.camera, looks) for state in states)
                count = write_video(path, progress(frames, len(states), f"video {name}", unit="frames"), fps,
                                    request.size, request.size)
                print(f"{name}: {count} frames ({len(states) - 1} steps and the final state) at {fps:g} fps, "
                      f"camera {request.camera} -> {pathlib.Path(path)}")
    return 0


def _check(request: ReplayRequest) -> int:
    from fetch._progress import progress

    with open_recording(request.file, request.demo) as recording:
        recording.require_valid()
        names = recording.names
        env = recording.replay_env()
        if note := recording.note(env):
            print(note)
        return _report(request.verbose, names,
                       progress((recording.check(name, env) for name in names), len(names), "replay"), env)


def _report(verbose: bool, names: list[str], checks: Any, env: Any) -> int:
    failures = 0
    largest: tuple[float, str] = (0.0, "")
    for r in checks:
        ok = r.exact and r.success_recorded == r.success_replayed
        failures += not ok
        dev = r.largest
        if dev.value >= largest[0]:
            largest = (dev.value, f"{r.name} {dev.where}")
        if not ok or verbose:
            success = "" if r.success_recorded == r.success_replayed else \
                f"; success recorded {r.success_recorded}, replayed {r.success_replayed}"
            verdict = "exact" if r.exact else f"DEVIATES; largest deviation {dev.value:.3g} at {dev.where}"
            print(f"{r.name}: {r.steps} steps, {verdict}{success}")
    env.close()
    print(f"replayed {len(names)} demo(s): {len(names) - failures} exact, {failures} deviating; largest "
          f"deviation {largest[0]:.3g}" + (f" ({largest[1]})" if largest[0] else ""))
    return 1 if failures else 0
