"""Reading a dataset: open with clear errors, list demos, load arrays, validate against the schema."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import pathlib
import reprlib
from collections.abc import Callable
from typing import Any

import h5py
import numpy as np

from fetch._confine import inside
from fetch._durable import BusyError
from fetch.dataset import schema
from fetch.dataset.demo_file import read_demo_group
from fetch.dataset.holding import editing, interrupted_renames
from fetch.dataset.sealed import check_index, check_sealed
from fetch.env import recorded_kwargs
from fetch.errors import DatasetError, FetchError, OutsideError, one_line
from fetch.tasks import ENV_IDS, MAX_STEPS

FILE_HELP = "a dataset file (demos.hdf5) or the directory that holds it"
"""The help of every subcommand's dataset argument (what `open_dataset` takes)."""
READ_ERRORS: tuple[type[Exception], ...] = (OSError, KeyError, RuntimeError, ValueError, TypeError)
"""What h5py raises on a damaged file; which one depends on the structure a damaged byte hit."""


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
        try:
            self.data_attrs: dict[str, Any] = {k: plain_value(v) for k, v in data.attrs.items()}
            keys = list(data.keys())
        except READ_ERRORS as e:
            raise DatasetError(f"{path}: its data attributes or list of demos cannot be read (the file is corrupt: "
                               f"{one_line(e)})") from e
        env_args = self._json_attr("env_args", None)
        if not isinstance(env_args, dict) or not isinstance(env_args.get("env_name"), str) \
                or not isinstance(env_args.get("env_kwargs", {}), dict):
            raise DatasetError(f"{path}: data.attrs['env_args'] is {self.data_attrs.get('env_args')!r}, not the JSON "
                               "object {env_name: str, type, env_kwargs: object} robomimic reads")
        if env_args["env_name"] not in ENV_IDS:  # Gymnasium would import the module before a ':' in it
            raise DatasetError(f"{path}: data.attrs['env_args'] names the env {env_args['env_name']!r}, which is not "
                               f"one of this package's ({', '.join(ENV_IDS)})")
        self.env_id: str = env_args["env_name"]
        try:  # they reach gym.make: only how rewards are given and how the scene looks may come from a file
            self.env_kwargs: dict[str, Any] = dict(recorded_kwargs(env_args.get("env_kwargs", {})))
        except FetchError as e:
            raise DatasetError(f"{path}: data.attrs['env_args']: {e}") from e
        try:
            self.layout = schema.layout_from_json(self.data_attrs["layout"])
        except (KeyError, ValueError, TypeError) as e:
            raise DatasetError(f"{path}: data.attrs['layout'] is missing or malformed ({e!r})") from e
        self.settings: dict[str, Any] = self._json_attr("settings", {})
        self.versions: dict[str, str] = self._json_attr("versions", {})
        for key, value in (("settings", self.settings), ("versions", self.versions)):
            if not isinstance(value, dict):
                raise DatasetError(f"{path}: data.attrs['{key}'] is {self.data_attrs[key]!r}, not a JSON object")
        limit = self.settings.get("max_steps", 1)  # an export's step limit (`export.env_spec`)
        if type(limit) is not int or not 1 <= limit <= MAX_STEPS:
            raise DatasetError(f"{path}: data.attrs['settings'] gives max_steps {reprlib.repr(limit)}, not a whole "
                               f"number of steps from 1 to {MAX_STEPS}")
        self._sealed: set[str] = set()
        """The demos checked to read nothing outside their files (`check_sealed`), when first read."""
        names = []
        for name in keys:
            try:
                names.append((schema.demo_index(name), name))
            except ValueError:
                continue  # validate() reports it
        self.demo_names: list[str] = [n for _, n in sorted(names)]

    def _json_attr(self, key: str, default: Any) -> Any:
        """`data.attrs[key]` decoded from JSON (`default` when absent); DatasetError naming it if it is not JSON."""
        if key not in self.data_attrs:
            if default is None:
                raise DatasetError(f"{self.path}: data.attrs['{key}'] is missing")
            return default
        try:
            return json.loads(self.data_attrs[key])
        except (ValueError, TypeError) as e:
            raise DatasetError(f"{self.path}: data.attrs['{key}'] is not valid JSON ({one_line(e)})") from e

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
        try:
            if "mask" not in self.file:
                return {}
            return {key: [n.decode() if isinstance(n, bytes) else str(n) for n in ds[()]]
                    for key, ds in self.file["mask"].items()}
        except READ_ERRORS as e:
            raise DatasetError(f"{self.path}: its masks cannot be read (the file is corrupt: {one_line(e)})") from e

    def demo(self, name: str) -> h5py.Group:
        """The group `data/<name>`; DatasetError if it is missing or its file cannot be read."""
        data = self.file["data"]
        if name not in data:
            raise DatasetError(f"{self.path} has no demo {name!r}; it has {len(self.demo_names)} demos "
                               f"({', '.join(self.demo_names[:3])}{', ...' if len(self.demo_names) > 3 else ''})")
        self._check_link(name)
        try:
            group = data[name]
        except READ_ERRORS as e:
            link = None
            with contextlib.suppress(*READ_ERRORS):
                link = data.get(name, getlink=True)
            where = ""
            if isinstance(link, h5py.ExternalLink):
                where = f" (its file {link.filename} next to {self.path.name})"
            raise DatasetError(f"{self.path}: demo {name!r} cannot be read{where}: {one_line(e)}") from e
        if not isinstance(group, h5py.Group):
            raise DatasetError(f"{self.path}: data/{name} is not a group")
        if name not in self._sealed:
            where = "" if group.file.filename == self.file.filename else f" (its file {group.file.filename})"
            try:
                check_sealed(group, f"{self.path}: demo {name!r}{where}")
            except READ_ERRORS as e:
                raise DatasetError(f"{self.path}: demo {name!r} cannot be read: {one_line(e)}") from e
            self._sealed.add(name)
        return group

    def _check_link(self, name: str) -> None:
        """DatasetError unless demo `name`, where the index links it to another file, links to a regular
        file inside the index's own directory: a downloaded dataset must not make the tools read (or
        `merge` copy) files elsewhere, nor block on a FIFO."""
        with contextlib.suppress(*READ_ERRORS):
            link = self.file["data"].get(name, getlink=True)
            if not isinstance(link, h5py.ExternalLink):
                return
            try:
                target = inside(self.path.parent, link.filename, f"demo {name!r}'s link")
            except OutsideError as e:
                raise OutsideError(f"{self.path}: demo {name!r} links to {link.filename}, outside the dataset's "
                                   f"directory {self.path.parent.resolve()}; a dataset's demo files live beside its "
                                   f"index ({schema.EPISODES_DIR}/)") from e
            if target.exists() and not target.is_file():
                raise DatasetError(f"{self.path}: demo {name!r} links to {link.filename}, which is not a regular file")

    def unlisted(self) -> list[pathlib.Path]:
        """Demo files beside a collector's index that it does not list: what a session stopped between
        saving a demo and rewriting the index left (the next `collect` on the directory takes them in)."""
        if self.path.name != schema.INDEX_NAME:
            return []
        listed = set()
        for name in self.demo_names:
            with contextlib.suppress(*READ_ERRORS):
                link = self.file["data"].get(name, getlink=True)
                if isinstance(link, h5py.ExternalLink):
                    listed.add(pathlib.PurePath(link.filename).name)
        found = self.path.parent / schema.EPISODES_DIR
        return sorted((f for f in found.glob("demo_*.hdf5") if f.name not in listed and f.is_file()),
                      key=lambda f: (len(f.name), f.name))

    def demo_file(self, name: str, write: bool = False) -> tuple[pathlib.Path, str]:
        """Where demo `name` is stored: (file, group path in it). A collector's dataset keeps each
        demo in its own file, linked from the index; a merged one keeps them in the index itself.
        `write`: the caller replaces that file, so no symbolic link may be on the way to it."""
        link = self.file["data"].get(name, getlink=True)
        if link is None:
            self.demo(name)  # raises, naming the valid choices
        if isinstance(link, h5py.ExternalLink):
            self._check_link(name)
            if write:
                inside(self.path.parent, link.filename, f"{self.path}: demo {name!r}'s link", write=True)
            return self.path.parent / link.filename, link.path
        return self.path, f"data/{name}"

    def arrays(self, name: str, keep: Callable[[str], bool] | None = None) -> dict[str, np.ndarray]:
        """Every array of one demo (or those whose path `keep` takes), loaded, keyed by its path in the demo
        group."""

        group = self.demo(name)
        try:
            return read_demo_group(group, keep).arrays
        except READ_ERRORS as e:
            raise DatasetError(f"{self.path}: demo {name!r} cannot be read: {one_line(e)}") from e

    def attrs(self, name: str) -> dict[str, Any]:
        group = self.demo(name)
        try:
            return {k: plain_value(v) for k, v in group.attrs.items()}
        except READ_ERRORS as e:
            raise DatasetError(f"{self.path}: demo {name!r} cannot be read: {one_line(e)}") from e

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


def plain_value(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def open_dataset(path: str | os.PathLike[str], mode: str = "r") -> Dataset:
    """Open a dataset written by this package; DatasetError naming the file if it is not one."""
    p = resolve(path)
    if p.name == schema.INDEX_NAME and p.is_symlink():  # a collector's index is its directory's content
        inside(p.parent, p.name, f"{p.parent}: the dataset's index")
    if not p.exists():
        raise DatasetError(f"{p}: no such file")
    if not p.is_file():  # a FIFO or a device would block the open, or read forever
        raise DatasetError(f"{p} is not a regular file; a dataset is an HDF5 file (or the directory that holds one)")
    if interrupted_renames(p) is not None:  # an edit stopped between its renames (the journal checked first):
        with contextlib.suppress(BusyError, OSError), editing(p):  # finish it, unless another tool holds it
            pass
    try:
        file = h5py.File(p, mode)
    except OSError as e:
        raise DatasetError(f"{p} is not a readable HDF5 file (corrupt, truncated or another format): {e}") from e
    try:
        return _checked(p, file)
    except READ_ERRORS as e:
        file.close()
        raise DatasetError(f"{p} cannot be read (the file is corrupt: {one_line(e)})") from e
    except BaseException:
        file.close()
        raise


def _checked(p: pathlib.Path, file: h5py.File) -> Dataset:
    data = file.get("data")
    if not isinstance(data, h5py.Group):
        raise DatasetError(f"{p} is an HDF5 file but not a demonstration dataset (it has no 'data' group)")
    fmt = plain_value(data.attrs.get("format"))
    if fmt != schema.FORMAT:
        raise DatasetError(f"{p} is not a gym-fetch-v2 dataset (data.attrs['format'] is {fmt!r}, expected "
                           f"{schema.FORMAT!r}); only datasets written by `gym-fetch collect` can be used here")
    check_index(file, str(p))
    raw = plain_value(data.attrs.get("format_version"))
    if not isinstance(raw, int) or isinstance(raw, bool) or raw < 1:
        raise DatasetError(f"{p}: data.attrs['format_version'] is {raw!r}, not a version number (1 to "
                           f"{schema.FORMAT_VERSION})")
    if raw > schema.FORMAT_VERSION:
        raise DatasetError(f"{p} has format version {raw}; this gym-fetch-v2 reads up to "
                           f"{schema.FORMAT_VERSION}: upgrade the package")
    return Dataset(p, file)


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
    corrections: tuple[int, int, int, int] = (0, 0, 0, 0)
    """Demos recorded with `--device takeover`: how many, the person's takeovers in them, the steps a
    person drove, and all their steps."""


def runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """The [start, end) steps of each run of non-zero values: in a demo's `intervention`, the stretches a
    person drove after taking over from a policy."""
    padded = np.concatenate([[0], np.asarray(flags) != 0, [0]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def takeovers(intervention: np.ndarray) -> int:
    """How often a person took over in one demo."""
    return len(runs(intervention))


def summarize(ds: Dataset) -> Summary:
    """The figures of the readable demos (`validate` says what is wrong with the others)."""
    unreadable: tuple[type[Exception], ...] = (DatasetError, *READ_ERRORS)
    lengths, successes, lows, highs, rates = [], 0, [], [], []
    devices: dict[str, int] = {}
    corrected = [0, 0, 0, 0]
    for name in ds.demo_names:
        try:
            group = ds.demo(name)
            attrs = group.attrs
            length, success = int(attrs["num_samples"]), bool(attrs["success"])
            actions = np.asarray(group["actions"][()], dtype=np.float64)
            rate = float(attrs.get("achieved_hz", 0.0))
            device = str(plain_value(attrs.get("device", "?")))
            person = np.asarray(group["intervention"][()]) if "intervention" in group else None
        except unreadable:
            continue
        if person is not None:
            corrected = [corrected[0] + 1, corrected[1] + takeovers(person), corrected[2] + int(person.sum()),
                         corrected[3] + len(person)]
        lengths.append(length)
        successes += success
        if actions.size and np.all(np.isfinite(actions)):
            lows.append(float(actions.min()))
            highs.append(float(actions.max()))
        rates.append(rate)
        devices[device] = devices.get(device, 0) + 1
    try:
        masks = {k: len(v) for k, v in ds.masks().items()}
    except DatasetError:
        masks = {}
    return Summary(
        path=ds.path, env_id=ds.env_id, demos=len(lengths), successful=successes, steps=sum(lengths),
        lengths=(min(lengths, default=0), max(lengths, default=0), float(np.mean(lengths)) if lengths else 0.0),
        action_range=(min(lows, default=0.0), max(highs, default=0.0)),
        achieved_hz=float(np.mean(rates)) if rates else 0.0, devices=devices,
        masks=masks, versions=ds.versions, cameras=ds.layout.cameras,
        corrections=(corrected[0], corrected[1], corrected[2], corrected[3]))
