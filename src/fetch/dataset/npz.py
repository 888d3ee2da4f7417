"""The seed's per-demo `.npz` files (`--format npz`), with its keys, for scripts that read them."""

from __future__ import annotations

import io
import json
import os
import pathlib
import re
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from fetch.dataset.episode import Demo
from fetch.dataset.writer import BackgroundWriter, atomic_write

_NUMBER = re.compile(r"_ep(\d+)_")


def seed_arrays(demo: Demo, metadata: dict[str, Any]) -> dict[str, Any]:
    """The seed's npz keys: `action`, `reward`, `terminated`, `truncated`, `obs__<key>` (T+1 rows,
    the reset's observation first), `metadata_json`, `info_json`; plus `states` (T+1 rows)."""
    a = demo.arrays
    packed: dict[str, Any] = {
        "metadata_json": json.dumps(metadata, ensure_ascii=False),
        # The seed stored the reset's info first, then one per step; the reset's is not recorded.
        "info_json": json.dumps([{}] + [{"is_success": float(s)} for s in a["is_success"]]),
        "action": a["actions"],
        "reward": a["rewards"].astype(np.float32),
        "terminated": a["terminated"],
        "truncated": a["truncated"],
        "states": a["states"],
    }
    for path in a:
        if path.startswith("obs/"):
            key = path[len("obs/"):]
            packed[f"obs__{key}"] = np.concatenate([a[path], a[f"next_obs/{key}"][-1:]])
    return packed


class NpzWriter(BackgroundWriter):
    """Writes each demo as `<env>_ep<NNNN>_<unix time>.npz` in `out_dir`, atomically; resumes numbering."""

    def __init__(self, out_dir: str | os.PathLike[str], env_id: str, metadata: dict[str, Any],
                 on_saved: Callable[[str, Demo], None] | None = None) -> None:
        super().__init__(out_dir, on_saved)
        self.env_id = env_id
        self.metadata = metadata
        for stale in self.out_dir.glob(".*.tmp"):
            stale.unlink()
        numbers = [int(m.group(1)) for p in self.out_dir.glob(f"{env_id}_ep*.npz") if (m := _NUMBER.search(p.name))]
        self._next_index = 1 + max(numbers, default=-1)
        self.saved = len(numbers)
        self.attempts = self._next_index
        self._start()

    def demo_name(self, index: int) -> str:
        return f"{self.env_id}_ep{index:04d}_{int(time.time())}"

    def _save(self, name: str, demo: Demo) -> None:
        metadata = {**self.metadata, **{k: _jsonable(v) for k, v in demo.attrs.items()},
                    "episode_index": int(_NUMBER.search(name).group(1)),  # type: ignore[union-attr]
                    "saved_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                    "successful": bool(demo.attrs["success"])}
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **seed_arrays(demo, metadata))
        atomic_write(pathlib.Path(self.out_dir) / f"{name}.npz", buffer.getvalue())


def _jsonable(value: Any) -> Any:
    return value.item() if isinstance(value, np.generic) else value

