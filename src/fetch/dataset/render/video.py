"""Video files of rendered frames: H.264 mp4 (plays everywhere) or gif, through PyAV.

PyAV bundles FFmpeg's libraries in its wheel (no ffmpeg program to install) and encodes from numpy
frames in-process. It is an optional dependency: `pip install ".[video]"`.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
from collections.abc import Iterable
from typing import Any

import numpy as np

from fetch._durable import temporary, why
from fetch.errors import FetchError, UnknownNameError, install_hint
from fetch.rendering import check_image_size

FORMATS = (".mp4", ".gif")

# A fixed 6x7x6 colour cube (252 colours) for gif: no per-video palette pass, and the frames of a
# video share one palette, so nothing flickers. Rows are ARGB, as PyAV takes them.
_LEVELS = (6, 7, 6)


def _gif_palette() -> np.ndarray:
    palette = np.zeros((256, 4), np.uint8)
    r, g, b = np.meshgrid(*(np.arange(n) for n in _LEVELS), indexing="ij")
    rgb = np.stack([c.ravel() * 255 // (n - 1) for c, n in zip((r, g, b), _LEVELS, strict=True)], axis=1)
    palette[: len(rgb), 0] = 255
    palette[: len(rgb), 1:] = rgb
    return palette


def _gif_indices(frame: np.ndarray) -> np.ndarray:
    """Each pixel's nearest colour of the palette (per channel: round to the level)."""
    levels = [np.rint(frame[..., c].astype(np.uint16) * (n - 1) / 255.0).astype(np.uint8)
              for c, n in enumerate(_LEVELS)]
    return (levels[0] * (_LEVELS[1] * _LEVELS[2]) + levels[1] * _LEVELS[2] + levels[2]).astype(np.uint8)


def check_video_path(path: str | os.PathLike[str], width: int, height: int) -> pathlib.Path:
    """The output path, after checking its format and the frame size (before any work)."""
    check_image_size(width, "--size")
    check_image_size(height, "--size")
    p = pathlib.Path(path)
    suffix = p.suffix.lower()
    if suffix not in FORMATS:
        raise UnknownNameError("video format", suffix or p.name, FORMATS)
    if suffix == ".mp4" and (width % 2 or height % 2):
        raise FetchError(f"an mp4 (H.264, yuv420p) needs an even width and height, got {width}x{height}")
    if not p.parent.is_dir():
        raise FetchError(f"cannot write {p}: the directory {p.parent} does not exist")
    _av()
    return p


def require_pyav() -> None:
    """FetchError with the install command unless PyAV can be imported: a check before long work
    (`eval --video` runs every episode first)."""
    _av()


def _av() -> Any:
    try:
        import av
    except ImportError as e:
        raise FetchError(f"writing video needs PyAV: {install_hint('video')}, or pip install av") from e
    return av


def write_video(path: str | os.PathLike[str], frames: Iterable[np.ndarray], fps: float, width: int,
                height: int) -> int:
    """Encode (H, W, 3) uint8 frames into `path` (.mp4 or .gif); returns the frame count.

    The file appears complete or not at all: it is written under a temporary name and renamed.
    """
    p = check_video_path(path, width, height)
    av = _av()
    gif = p.suffix.lower() == ".gif"
    try:
        tmp = temporary(p)
    except OSError as e:
        raise FetchError(f"cannot write {p}: {why(e)}") from e
    count = 0
    try:
        with av.open(str(tmp), "w", format="gif" if gif else "mp4") as container:
            rate = max(1, round(fps))
            stream = container.add_stream("gif" if gif else "libx264", rate=rate)
            stream.width, stream.height = width, height
            stream.pix_fmt = "pal8" if gif else "yuv420p"
            if not gif:
                stream.options = {"crf": "18"}  # visually lossless for renders; small anyway
            palette = _gif_palette() if gif else None
            for frame in frames:
                if frame.shape != (height, width, 3) or frame.dtype != np.uint8:
                    raise FetchError(f"frame {count} is {frame.dtype} {frame.shape}, expected uint8 "
                                     f"({height}, {width}, 3)")
                image = av.VideoFrame.from_ndarray((_gif_indices(frame), palette), format="pal8") if gif \
                    else av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")
                for packet in stream.encode(image):
                    container.mux(packet)
                count += 1
            for packet in stream.encode():
                container.mux(packet)
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return count


def read_video(path: str | os.PathLike[str]) -> tuple[np.ndarray, float]:
    """Decode a video into (N, H, W, 3) uint8 frames and its frame rate (for tests and checks)."""
    av = _av()
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(stream)]
        rate = float(stream.average_rate or stream.base_rate or 0)
    return np.stack(frames) if frames else np.empty((0, 0, 0, 3), np.uint8), rate
