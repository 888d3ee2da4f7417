"""collect_fetch_demo.py's per-demo `.npz` files (`--format npz`), with its keys, for scripts that read them."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import pathlib
import re
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from fetch._durable import atomic_write
from fetch.dataset import schema
from fetch.dataset.background import BackgroundWriter
from fetch.dataset.episode import Demo
from fetch.errors import DatasetError

_NUMBER = re.compile(r"_ep(\d+)_")


def file_stem(env_id: str, index: int, unix_time: float) -> str:
    """collect_fetch_demo.py's name of its `index`-th saved demo, without `.npz`: `<env>_ep<NNNN>_<unix time [s]>`."""
    return f"{env_id}_ep{index:04d}_{int(unix_time)}"


def seed_metadata(base: dict[str, Any], demo: Demo, index: int, saved: float) -> dict[str, Any]:
    """A file's `metadata_json`: the session's `base`, the demo's attributes, and collect_fetch_demo.py's per-demo keys
    (`episode_index`, `saved_utc` from `saved` [s, Unix time], `successful`)."""
    return {**base, **{k: _jsonable(v) for k, v in demo.attrs.items()}, "episode_index": index,
            "saved_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(saved)),
            "successful": bool(demo.attrs["success"])}


def seed_file(demo: Demo, metadata: dict[str, Any]) -> bytes:
    """The bytes of one demo's `.npz` file (compressed, as the seed wrote it)."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **seed_arrays(demo, metadata))
    return buffer.getvalue()


def seed_arrays(demo: Demo, metadata: dict[str, Any]) -> dict[str, Any]:
    """collect_fetch_demo.py's npz keys: `action`, `reward`, `terminated`, `truncated`, `obs__<key>` (T+1 rows,
    the reset's observation first), `metadata_json`, `info_json`; plus `states` (T+1 rows) and
    `expert_action`: what the device meant at each step, the expert's clean action where `action` is
    its DART-perturbed one (what to learn; `action` replays); a demo a person corrected adds
    `intervention` (1 where the person drove) and `policy_action` (what the policy proposed), T rows."""
    a = demo.arrays
    packed: dict[str, Any] = {
        "metadata_json": json.dumps(metadata, ensure_ascii=False),
        # The seed stored the reset's info first, then one per step; the reset's is not recorded.
        "info_json": json.dumps([{}] + [{"is_success": float(s)} for s in a["is_success"]]),
        "action": a["actions"],
        "expert_action": schema.meant_actions(a),
        "reward": a["rewards"].astype(np.float32),
        "terminated": a["terminated"],
        "truncated": a["truncated"],
        "states": a["states"],
    }
    if "intervention" in a:  # corrected by a person (`--device takeover`)
        packed["intervention"] = a["intervention"]
        packed["policy_action"] = a["policy_actions"]
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
        return file_stem(self.env_id, index, time.time())

    def _save(self, name: str, demo: Demo) -> None:
        index = int(_NUMBER.search(name).group(1))  # type: ignore[union-attr]
        metadata = seed_metadata(self.metadata, demo, index, time.time())
        atomic_write(pathlib.Path(self.out_dir) / f"{name}.npz", seed_file(demo, metadata))


def _jsonable(value: Any) -> Any:
    return value.item() if isinstance(value, np.generic) else value



# -- reading: `gym-fetch info` and `replay --check` on a directory of collect_fetch_demo.py's files --------------


@dataclasses.dataclass(frozen=True)
class NpzDemo:
    """One `.npz` file: its metadata and arrays (`action`, `states`, `obs__<key>`, ...)."""

    path: pathlib.Path
    metadata: dict[str, Any]
    arrays: dict[str, np.ndarray]

    @property
    def steps(self) -> int:
        return int(len(self.arrays["action"]))


def npz_files(path: str | os.PathLike[str]) -> list[pathlib.Path]:
    """The seed-format files a path names: a directory's `*_ep<NNNN>_*.npz` files in order, or one `.npz`
    file; [] when there are none (an HDF5 dataset, or nothing)."""
    p = pathlib.Path(path)
    if p.is_file():
        return [p] if p.suffix == ".npz" else []
    if not p.is_dir() or (p / "demos.hdf5").exists():
        return []
    return sorted((f for f in p.glob("*.npz") if _NUMBER.search(f.name)),
                  key=lambda f: int(_NUMBER.search(f.name).group(1)))  # type: ignore[union-attr]


def load_npz(path: pathlib.Path) -> NpzDemo:
    """Read one file; DatasetError naming it if it is not a readable seed-format demo."""
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
        metadata = json.loads(str(arrays.pop("metadata_json")))
    except (OSError, ValueError, KeyError) as e:
        raise DatasetError(f"{path}: not a readable demo file of `collect --format npz` ({e})") from e
    missing = [k for k in ("action", "states", "info_json") if k not in arrays]
    missing += [k for k in ("env_id", "seed") if k not in metadata]
    if missing:
        raise DatasetError(f"{path}: lacks {', '.join(missing)}; files written before states were added to the "
                           "npz format cannot be replayed (record with the default --format hdf5 for that)")
    return NpzDemo(path, metadata, arrays)


def problems(demo: NpzDemo) -> list[str]:
    """What is inconsistent in one file (empty if nothing)."""
    a, t, out = demo.arrays, demo.steps, []
    if a["action"].ndim != 2 or a["action"].shape[1:] != (4,):
        out.append(f"{demo.path.name}: action has shape {a['action'].shape}, expected (T, 4)")
    elif not np.isfinite(a["action"]).all():
        out.append(f"{demo.path.name}: action holds NaN or infinite values")
    if "expert_action" in a and a["expert_action"].shape != a["action"].shape:
        out.append(f"{demo.path.name}: expert_action has shape {a['expert_action'].shape}, expected action's "
                   f"{a['action'].shape}")
    for key, value in a.items():
        if (key.startswith("obs__") or key == "states") and len(value) != t + 1:
            out.append(f"{demo.path.name}: {key} has {len(value)} rows, expected T+1 = {t + 1}")
    return out
