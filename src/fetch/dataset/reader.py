"""Reading a dataset: open with clear errors, list demos, load arrays, validate against the schema."""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
from typing import Any

import h5py
import numpy as np

from fetch.dataset import schema
from fetch.errors import DatasetError


def resolve(path: str | os.PathLike[str]) -> pathlib.Path:
    """A dataset file, given it or the output directory that holds it."""
    p = pathlib.Path(path)
    return p / schema.INDEX_NAME if p.is_dir() else p


class Dataset:
    """An open dataset (read-only unless opened with mode "r+"). Use as a context manager."""

    def __init__(self, path: pathlib.Path, file: h5py.File) -> None:
        self.path = path
        self.file = file
        data = file["data"]
        self.data_attrs: dict[str, Any] = {k: _plain(v) for k, v in data.attrs.items()}
        try:
            env_args = json.loads(self.data_attrs["env_args"])
            self.env_id: str = env_args["env_name"]
            self.env_kwargs: dict[str, Any] = dict(env_args.get("env_kwargs", {}))
            self.layout = schema.layout_from_json(self.data_attrs["layout"])
            self.settings: dict[str, Any] = json.loads(self.data_attrs.get("settings", "{}"))
            self.versions: dict[str, str] = json.loads(self.data_attrs.get("versions", "{}"))
        except (KeyError, ValueError, TypeError) as e:
            raise DatasetError(f"{path}: its data attributes are incomplete or malformed ({e!r})") from e
        names = []
        for name in data.keys():
            try:
                names.append((schema.demo_index(name), name))
            except ValueError:
                continue  # validate() reports it
        self.demo_names: list[str] = [n for _, n in sorted(names)]

    def __enter__(self) -> Dataset:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.file.close()

    def header_attrs(self) -> dict[str, Any]:
        """The fields a resumed session must match (see `DatasetWriter`)."""
        return {"env_id": self.env_id, "env_kwargs": self.env_kwargs, "layout": self.data_attrs["layout"],
                "settings": self.settings, "model_hash": self.data_attrs.get("model_hash")}

    def masks(self) -> dict[str, list[str]]:
        if "mask" not in self.file:
            return {}
        return {key: [n.decode() if isinstance(n, bytes) else str(n) for n in ds[()]]
                for key, ds in self.file["mask"].items()}

    def demo(self, name: str) -> h5py.Group:
        """The group `data/<name>`; DatasetError if it is missing or its file cannot be read."""
        data = self.file["data"]
        if name not in data:
            raise DatasetError(f"{self.path} has no demo {name!r}; it has {len(self.demo_names)} demos "
                               f"({', '.join(self.demo_names[:3])}{', ...' if len(self.demo_names) > 3 else ''})")
        try:
            group = data[name]
        except (KeyError, OSError) as e:
            link = data.get(name, getlink=True)
            where = ""
            if isinstance(link, h5py.ExternalLink):
                where = f" (its file {link.filename} next to {self.path.name})"
            raise DatasetError(f"{self.path}: demo {name!r} cannot be read{where}: {e}") from e
        if not isinstance(group, h5py.Group):
            raise DatasetError(f"{self.path}: data/{name} is not a group")
        return group

    def demo_file(self, name: str) -> tuple[pathlib.Path, str]:
        """Where demo `name` is stored: (file, group path in it). A collector's dataset keeps each
        demo in its own file, linked from the index; a merged one keeps them in the index itself."""
        link = self.file["data"].get(name, getlink=True)
        if link is None:
            self.demo(name)  # raises, naming the valid choices
        if isinstance(link, h5py.ExternalLink):
            return self.path.parent / link.filename, link.path
        return self.path, f"data/{name}"

    def arrays(self, name: str) -> dict[str, np.ndarray]:
        """Every array of one demo, loaded, keyed by its path in the demo group."""
        from fetch.dataset.writer import read_demo_group

        return read_demo_group(self.demo(name)).arrays

    def attrs(self, name: str) -> dict[str, Any]:
        return {k: _plain(v) for k, v in self.demo(name).attrs.items()}

    def select(self, demo: int | str | None) -> list[str]:
        """Demo names for a `--demo` argument: all (None), an index, or a name."""
        if demo is None:
            return list(self.demo_names)
        if isinstance(demo, str) and not demo.startswith("demo_") and not demo.isdigit():
            shown = ", ".join(self.demo_names[:5]) + (" ..." if len(self.demo_names) > 5 else "")
            raise DatasetError(f"--demo {demo!r} is neither an index nor a demo name; {self.path} has {shown}")
        name = demo if isinstance(demo, str) and demo.startswith("demo_") else schema.demo_name(int(demo))
        self.demo(name)  # raises with the valid choices
        return [name]


def _plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def open_dataset(path: str | os.PathLike[str], mode: str = "r") -> Dataset:
    """Open a dataset written by this package; DatasetError naming the file if it is not one."""
    p = resolve(path)
    if not p.exists():
        raise DatasetError(f"{p}: no such file")
    try:
        file = h5py.File(p, mode)
    except OSError as e:
        raise DatasetError(f"{p} is not a readable HDF5 file (corrupt, truncated or another format): {e}") from e
    try:
        data = file.get("data")
        if not isinstance(data, h5py.Group):
            raise DatasetError(f"{p} is an HDF5 file but not a demonstration dataset (it has no 'data' group)")
        fmt = _plain(data.attrs.get("format"))
        if fmt != schema.FORMAT:
            raise DatasetError(f"{p} is not a gym-fetch-v2 dataset (data.attrs['format'] is {fmt!r}, expected "
                               f"{schema.FORMAT!r}); only datasets written by `gym-fetch collect` can be used here")
        version = int(_plain(data.attrs.get("format_version", 0)))
        if version > schema.FORMAT_VERSION:
            raise DatasetError(f"{p} has format version {version}; this gym-fetch-v2 reads up to "
                               f"{schema.FORMAT_VERSION}: upgrade the package")
        return Dataset(p, file)
    except BaseException:
        file.close()
        raise


@dataclasses.dataclass(frozen=True)
class Summary:
    """What `gym-fetch info` prints."""

    path: pathlib.Path
    env_id: str
    demos: int
    successful: int
    steps: int
    lengths: tuple[int, int, float]  # min, max, mean
    action_range: tuple[float, float]
    achieved_hz: float
    devices: dict[str, int]
    masks: dict[str, int]
    versions: dict[str, str]
    cameras: tuple[str, ...]


def summarize(ds: Dataset) -> Summary:
    lengths, successes, lows, highs, rates = [], 0, [], [], []
    devices: dict[str, int] = {}
    for name in ds.demo_names:
        try:
            group = ds.demo(name)
            attrs = group.attrs
            attrs["num_samples"], attrs["success"]  # noqa: B018 (readable? validate() says what is wrong)
        except (DatasetError, KeyError):
            continue
        lengths.append(int(attrs["num_samples"]))
        successes += bool(attrs["success"])
        actions = group["actions"][()]
        if len(actions):
            lows.append(float(actions.min()))
            highs.append(float(actions.max()))
        rates.append(float(attrs.get("achieved_hz", 0.0)))
        device = str(_plain(attrs.get("device", "?")))
        devices[device] = devices.get(device, 0) + 1
    return Summary(
        path=ds.path, env_id=ds.env_id, demos=len(lengths), successful=successes, steps=sum(lengths),
        lengths=(min(lengths, default=0), max(lengths, default=0), float(np.mean(lengths)) if lengths else 0.0),
        action_range=(min(lows, default=0.0), max(highs, default=0.0)),
        achieved_hz=float(np.mean(rates)) if rates else 0.0, devices=devices,
        masks={k: len(v) for k, v in ds.masks().items()}, versions=ds.versions, cameras=ds.layout.cameras)


def validate(ds: Dataset) -> list[str]:
    """Every inconsistency found in the file (empty when it is sound); each names the demo and key."""
    problems: list[str] = []
    data = ds.file["data"]
    for name in data.keys():
        try:
            schema.demo_index(name)
        except ValueError:
            problems.append(f"data/{name}: not a demo name (demo_<integer>)")
    total = 0
    unreadable = set()
    for name in ds.demo_names:
        try:
            group = ds.demo(name)
        except DatasetError as e:
            problems.append(str(e))
            unreadable.add(name)
            continue
        missing = [key for key, _ in schema.DEMO_ATTRS if key not in group.attrs]
        if missing:
            problems.append(f"{name}: missing attributes {', '.join(missing)}")
            unreadable.add(name)
            continue
        t = int(group.attrs["num_samples"])
        total += t
        layout = ds.layout
        arrays: dict[str, h5py.Dataset] = {}

        def visit(path: str, node: Any, into: dict[str, Any] = arrays) -> None:
            if isinstance(node, h5py.Dataset):
                into[path] = node

        group.visititems(visit)
        shape_problems = schema.check_arrays(arrays, layout, t)
        images = {f"missing {p}/{schema.image_key(c)}" for c in layout.cameras for p in ("obs", "next_obs")}
        if shape_problems and set(shape_problems) <= images:
            problems.append(f"{name}: its images are not rendered yet (the collector stopped first): run "
                            "`gym-fetch collect` on this directory again, or `gym-fetch render-obs --overwrite`")
            continue
        if shape_problems:
            problems += [f"{name}: {p}" for p in shape_problems]
            continue
        actions = arrays["actions"][()]
        if t and (not np.all(np.isfinite(actions)) or np.abs(actions).max() > 1.0):
            problems.append(f"{name}: actions outside [-1, 1] (robomimic rejects them)")
        for key, _ in layout.obs_sizes:
            obs, nxt = arrays[f"obs/{key}"][()], arrays[f"next_obs/{key}"][()]
            if t > 1 and not np.array_equal(obs[1:], nxt[:-1]):
                problems.append(f"{name}: next_obs/{key}[t] differs from obs/{key}[t+1]")
        dones = arrays["dones"][()]
        if t and (dones[-1] != 1 or dones[:-1].any()):
            problems.append(f"{name}: dones must be 1 at the last step only")
        success = bool(group.attrs["success"])
        if success and t and not arrays["is_success"][()].any():
            problems.append(f"{name}: marked successful but is_success is never 1")
        if str(_plain(group.attrs["env_id"])) != ds.env_id:
            problems.append(f"{name}: env_id {group.attrs['env_id']!r} differs from the dataset's {ds.env_id!r}")
    if int(ds.data_attrs.get("total", -1)) != total:
        problems.append(f"data.attrs['total'] is {ds.data_attrs.get('total')}, the demos hold {total} steps")
    masks = ds.masks()
    names = set(ds.demo_names)
    for key, listed in masks.items():
        problems += [f"mask/{key} lists {n}, which is not in data" for n in listed if n not in names]
    # Every demo is in exactly one of the three splits (other filter keys, as robomimic allows, may overlap).
    split_of: dict[str, str] = {}
    for key in schema.SPLITS:
        for n in masks.get(key, []):
            if n in split_of:
                problems.append(f"{n} is in both mask/{split_of[n]} and mask/{key}")
            split_of.setdefault(n, key)
    problems += [f"{n} is in no mask (train, valid or failed)" for n in ds.demo_names if n not in split_of]
    for key in schema.SPLITS:
        for n in masks.get(key, []):
            if n in names and n not in unreadable:
                success = bool(ds.demo(n).attrs["success"])
                if success != (key != "failed"):
                    problems.append(f"{n} is in mask/{key} but its success is {success}")
    return problems
