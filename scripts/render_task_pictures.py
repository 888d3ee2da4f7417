"""Render one picture per task into docs/images/ for the README's task table."""

from __future__ import annotations

import argparse
import pathlib
import zlib

import gymnasium as gym
import numpy as np

import fetch


def write_png(path: pathlib.Path, image: np.ndarray) -> None:
    """A minimal RGB PNG writer (no imaging dependency for one script)."""
    height, width, _ = image.shape
    raw = b"".join(b"\x00" + image[row].tobytes() for row in range(height))

    def chunk(kind: bytes, payload: bytes) -> bytes:
        body = kind + payload
        return len(payload).to_bytes(4, "big") + body + zlib.crc32(body).to_bytes(4, "big")

    header = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([8, 2, 0, 0, 0])
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9))
                     + chunk(b"IEND", b""))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path(__file__).parents[1] / "docs" / "images")
    parser.add_argument("--camera", default="side")
    parser.add_argument("--size", type=int, nargs=2, default=(320, 240), metavar=("W", "H"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for env_id in fetch.ENV_IDS:
        env = gym.make(env_id, render_mode="rgb_array", width=args.size[0], height=args.size[1],
                       camera_name=args.camera)
        env.reset(seed=1)
        path = args.out / f"{env_id}.png"
        write_png(path, env.render())
        env.close()
        print(path)


if __name__ == "__main__":
    main()
