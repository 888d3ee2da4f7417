"""Exports of a dataset: a Minari dataset (`minari.load_dataset` opens it), collect_fetch_demo.py's per-demo
npz files and a LeRobotDataset (`lerobot_writer.py`). The `export` subcommand and its formats: `exporters.py`."""

from __future__ import annotations

import dataclasses
import os
import pathlib
import re
import shutil
import warnings
from typing import Any

import numpy as np

from fetch._durable import lock_directory, unlock_directory
from fetch.dataset import npz, schema
from fetch.dataset.dirs import env_dir, recover_replaced, replacing_dir, require_apart
from fetch.dataset.episode import Demo
from fetch.dataset.reader import Dataset, one_line, open_dataset
from fetch.dataset.validation import require_valid
from fetch.errors import DatasetError, FetchError, UnknownNameError, install_hint

SELECTIONS = ("successful", "all")
"""`--demos` choices besides the masks a file holds (train, valid, failed, ...)."""
MINARI_INSTALL = install_hint("minari")
_DATASET_ID = re.compile(r"(?:(?:[-\w]{2,}|[-\w]+(?:/[-\w]+)+)/)?[-\w]+-v\d+")
"""Minari's `(namespace/)name-v<version>` (`minari.dataset.minari_dataset.DATASET_ID_RE`, matched whole): a
namespace of at least 2 characters, nested with '/'. Stricter than Minari in two places, where Minari writes
a dataset it cannot read back: the version is required (without one it fails on load), and a namespace has
no empty part (`a//b` is written as `a/b`, which `list_local_datasets` leaves out)."""
_SPACE_PER_EPISODE = 64 << 10
_SPACE_MARGIN = 1 << 20
"""What a Minari export needs besides the arrays [bytes]: per episode (its HDF5 groups and headers) and in
all (the metadata, the file's headers), with room to spare."""


@dataclasses.dataclass(frozen=True)
class Exported:
    """What an export wrote: where, the source demos it holds (in order), their steps, and where its videos'
    frames came from (LeRobot: `videos`)."""

    path: pathlib.Path
    demos: tuple[str, ...]
    steps: int
    videos: str = ""


def select_demos(ds: Dataset, which: str) -> dict[str, dict[str, Any]]:
    """The demos for `--demos` (successful ones, all, or those of a mask), in the file's order, with
    their attributes. Demos without a step are left out: a Minari episode needs at least one."""
    masks = ds.masks()
    if which not in SELECTIONS and which not in masks:
        raise UnknownNameError("demo selection", which, SELECTIONS + tuple(sorted(masks)))
    listed = set(ds.demo_names if which in SELECTIONS else masks[which])
    chosen = {n: ds.attrs(n) for n in ds.demo_names if n in listed}
    chosen = {n: a for n, a in chosen.items()
              if int(a["num_samples"]) > 0 and (which != "successful" or bool(a["success"]))}
    if not chosen:
        raise DatasetError(f"{ds.path}: no demo to export with --demos {which} (the file holds "
                           f"{len(ds.demo_names)} demos; try --demos all)")
    return chosen


def env_spec(ds: Dataset, *, evaluation: bool = False) -> Any:
    """The Gymnasium `EnvSpec` of the demos' env: the registered id with the recorded `env_kwargs`
    and the collector's step limit (`--max-steps`), or with `evaluation` the task's registered one."""
    import gymnasium as gym

    import fetch

    try:
        spec = gym.spec(ds.env_id)
    except gym.error.Error as e:
        raise UnknownNameError("env", ds.env_id, fetch.ENV_IDS) from e
    limit = spec.max_episode_steps if evaluation else ds.settings.get("max_steps", spec.max_episode_steps)
    return dataclasses.replace(spec, kwargs={**spec.kwargs, **ds.env_kwargs},
                               max_episode_steps=None if limit is None else int(limit))


def default_dataset_id(env_id: str, devices: list[str], demos: str = "successful") -> str:
    """`fetch/<task>/<device>-v0`, e.g. `fetch/drawer-open/expert-v0` (`mixed` for several devices);
    another `--demos` than the default is named too, e.g. `fetch/drawer-open/expert-valid-v0`."""
    task = env_id.rsplit("-v", 1)[0].lower()
    name = devices[0] if len(devices) == 1 else "mixed"
    if demos != "successful":
        # A mask's name is the file's: whatever Minari's id syntax does not allow becomes '-'.
        name += "-" + re.sub(r"[^-\w]+", "-", demos)
    return f"fetch/{task}/{name}-v0"


def _devices(demos: dict[str, dict[str, Any]]) -> list[str]:
    return sorted({str(attrs.get("device", "unknown")) for attrs in demos.values()})


def _import_minari() -> Any:
    try:
        import minari
    except ImportError as e:
        raise FetchError(f"--to minari needs the minari package, which cannot be imported ({e}); "
                         f"install it with: {MINARI_INSTALL}") from e
    return minari


def minari_root() -> pathlib.Path:
    """Where Minari keeps local datasets: $MINARI_DATASETS_PATH (a relative one from the current
    directory, as Minari takes it; an empty one is an error, `dirs.env_dir`), else ~/.minari/datasets."""
    root = env_dir("MINARI_DATASETS_PATH", "~/.minari/datasets")
    return (root if root is not None else pathlib.Path.home() / ".minari" / "datasets").absolute()


def export_minari(ds_path: str | os.PathLike[str], dataset_id: str | None = None, *, demos: str = "successful",
                  force: bool = False, author: str | None = None, author_email: str | None = None,
                  code_permalink: str | None = None, description: str | None = None) -> Exported:
    """Write the selected demos as the local Minari dataset `dataset_id` (under `minari_root()`).

    Each episode holds T+1 observations for T actions (`obs` then the last `next_obs`), its reset
    seed, and `infos["is_success"]` and `infos["expert_action"]` (T+1 rows: the reset's, then each
    step's; a step's expert action is what the device meant where it applied `actions[t]`, the
    expert's clean action under DART noise: what to learn; the reset's row is NaN), and for demos a
    person corrected `infos["intervention"]` and `infos["policy_action"]` likewise. Its last step is
    marked truncated unless the env terminated it, as Minari's own collector does. The env spec
    re-creates the env the demos were recorded in; the eval env spec is that env with the task's
    registered step limit. Recorded camera images are in the observations but not in a recovered
    env's: the description says how to render them. An existing dataset of the same id is an error
    unless `force`; a failed export leaves no dataset behind. The id's directory must lie apart from the
    input (`dirs.require_apart`), and the disk must have room for the estimate `_space_needed` before
    anything is written: Minari's HDF5 writes on a full disk can crash the process.
    """
    minari = _import_minari()
    with open_dataset(ds_path) as ds:
        require_valid(ds)  # nothing a tool flags as invalid is passed on
        chosen = select_demos(ds, demos)
        devices = _devices(chosen)
        dataset_id = dataset_id or default_dataset_id(ds.env_id, devices, demos)
        if not _DATASET_ID.fullmatch(dataset_id):
            raise FetchError(f"bad Minari dataset id {dataset_id!r}: it must read (namespace/)name-v<version> "
                             "with letters, digits, '-' and '_', a namespace of at least 2 characters (Minari's "
                             "rule) and one '/' between its parts, e.g. fetch/drawer-open/expert-v0")
        root = minari_root()
        target = root / dataset_id
        require_apart(target, [ds_path], what=f"the Minari dataset {dataset_id!r} at",
                      remedy="choose a --dataset-id or MINARI_DATASETS_PATH outside the input")
        _require_space(target, _space_needed(ds, chosen))
        # The collection env keeps --max-steps, as recorded: a kept failure ran to that limit and replays
        # in it. The eval env has the task's registered limit, so that its scores compare with others'.
        spec, eval_spec = env_spec(ds), env_spec(ds, evaluation=True)
        description = description or (f"{len(chosen)} {ds.env_id} demonstrations ({', '.join(devices)}) "
                                      f"recorded with gym-fetch-v2, exported from {ds.path.name}. Its env needs "
                                      "the gym-fetch-v2 package (import fetch), which installs from its source "
                                      "tree; Minari's requirements list leaves it out, as pip cannot find it "
                                      "on PyPI")
        if ds.layout.cameras:
            description = f"{description.rstrip().rstrip('.')}. {_images_note(ds.layout)}"
        metadata = {"algorithm_name": ", ".join(devices), "author": author, "author_email": author_email,
                    "code_permalink": code_permalink, "description": description}
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise DatasetError(f"cannot create {target.parent} for the Minari dataset: {e}") from e
        handle = lock_directory(target.parent, "export under another --dataset-id")
        try:
            recover_replaced(target)  # before the check: a dataset a killed --force export set aside is there
            if target.exists() and not force:
                raise DatasetError(f"a Minari dataset {dataset_id!r} already exists at {target}; choose another id "
                                   "(e.g. the next version, -v1) or pass --force to replace it")
            with replacing_dir(target, force=True, what=f"the Minari dataset {dataset_id!r}") as building:
                steps = _staged_minari(minari, root, dataset_id, ds, chosen, spec, eval_spec, metadata, building)
        finally:
            unlock_directory(handle)
    return Exported(path=target, demos=tuple(chosen), steps=steps)


def _space_needed(ds: Dataset, chosen: dict[str, dict[str, Any]]) -> int:
    """An upper bound on the disk space the Minari export of `chosen` takes [bytes]: the demos' arrays as
    recorded (Minari keeps less: one copy of the observations where the file has obs and next_obs, and no
    states), plus `_SPACE_PER_EPISODE` each and `_SPACE_MARGIN`. Read from the arrays' shapes, not their data."""
    import h5py

    sizes: list[int] = []

    def add(_: str, item: object) -> None:
        if isinstance(item, h5py.Dataset):
            sizes.append(item.nbytes)

    for name in chosen:
        ds.demo(name).visititems(add)
    return sum(sizes) + _SPACE_PER_EPISODE * len(chosen) + _SPACE_MARGIN


def _require_space(target: pathlib.Path, need: int) -> None:
    """DatasetError unless the file system `target` goes on (that of its nearest existing directory) has
    `need` bytes free: Minari's HDF5 writes on a full disk end in a segfault or an HDF5 traceback, and an
    old dataset under the id is replaced only once the new one is whole, so the space is needed in full."""
    place = target
    while not place.is_dir():
        place = place.parent
    free = shutil.disk_usage(place).free
    if free < need:
        raise DatasetError(f"not enough disk space for the Minari dataset at {target}: {place} has {_mib(free)} "
                           f"free and the export needs about {_mib(need)}; free some space or set "
                           "MINARI_DATASETS_PATH to a directory on another disk")


def _mib(n: int) -> str:
    return f"{n / (1 << 20):.1f} MiB"


def _staged_minari(minari: Any, root: pathlib.Path, dataset_id: str, ds: Dataset, chosen: dict[str, dict[str, Any]],
                   spec: Any, eval_spec: Any, metadata: dict[str, Any], building: pathlib.Path) -> int:
    """Write the dataset into `building` (`dirs.replacing_dir` swaps it in whole: a kill at any instant
    leaves the old dataset or the new one under its id, never a part; a killed export left a broken
    dataset there in 4 of 8 trials). Minari writes under $MINARI_DATASETS_PATH/<id>, so it writes under
    a hidden staging root beside the others (Minari lists no hidden directory), moved into `building`.
    What Minari's writes raise (OSError, HDF5's RuntimeError: a full disk, a write error) is a
    DatasetError naming the dataset; nothing is left of the staging root."""
    import gymnasium as gym

    staging = root / f".partial-{dataset_id.replace('/', '--')}"
    shutil.rmtree(staging, ignore_errors=True)  # what a killed export left
    before = os.environ.get("MINARI_DATASETS_PATH")
    env = gym.make(spec)
    try:
        os.environ["MINARI_DATASETS_PATH"] = str(staging)
        try:
            steps = _write_minari(minari, dataset_id, ds, chosen, env, eval_spec, metadata)
        finally:
            if before is None:
                os.environ.pop("MINARI_DATASETS_PATH", None)
            else:
                os.environ["MINARI_DATASETS_PATH"] = before
        (staging / dataset_id).rename(building)  # onto the empty directory
    except (OSError, RuntimeError) as e:
        raise DatasetError(f"cannot write the Minari dataset {dataset_id!r} at {root / dataset_id}: "
                           f"{one_line(e)}") from e
    finally:
        env.close()
        shutil.rmtree(staging, ignore_errors=True)
    return steps


def _write_minari(minari: Any, dataset_id: str, ds: Dataset, chosen: dict[str, dict[str, Any]], env: Any,
                  eval_spec: Any, metadata: dict[str, Any]) -> int:
    """Create the Minari dataset and add the demos one at a time (the whole dataset never sits in
    memory: with images it would not fit); the steps written."""
    from fetch._progress import progress

    with warnings.catch_warnings():
        # Minari asks for each metadata field it was not given; leaving one out is a choice here.
        warnings.filterwarnings("ignore", message=r"`\w+` is set to None", category=UserWarning)
        dataset = minari.create_dataset_from_buffers(
            dataset_id, [], env=env, eval_env=eval_spec, action_space=env.action_space,
            observation_space=_observation_space(env.observation_space, ds.layout), data_format="hdf5",
            requirements=[], jpeg_encoding=False, **metadata)  # gym-fetch-v2 is not on PyPI: the description says
    from minari.data_collector import EpisodeBuffer

    steps = 0
    corrected = any("intervention" in ds.demo(name) for name in chosen)  # then every episode has the keys
    for name in progress(chosen, len(chosen), "export"):
        episode = _episode(ds.arrays(name), chosen[name], env.unwrapped, corrected)
        dataset.storage.update_episodes([EpisodeBuffer(**episode)])
        steps += len(episode["rewards"])
    dataset.storage.update_episode_metadata(
        [{"demo": n, "success": bool(a["success"])} for n, a in chosen.items()], range(len(chosen)))
    return steps


def _observation_space(space: Any, layout: schema.Layout) -> Any:
    """The env's observation space plus the recorded camera images (uint8, H x W x 3)."""
    if not layout.cameras:
        return space
    import gymnasium as gym

    size = layout.image_size
    images = {schema.image_key(c): gym.spaces.Box(0, 255, (size, size, 3), np.uint8) for c in layout.cameras}
    return gym.spaces.Dict({**space.spaces, **images})


def _images_note(layout: schema.Layout) -> str:
    """The description's sentence on the recorded images, which a recovered env does not observe."""
    keys = ", ".join(schema.image_key(c) for c in layout.cameras)
    # The env's camera observations use the renderer, size and quality the dataset's images were made with.
    recipe = (f"recover_environment(cameras={tuple(layout.cameras)!r}, image_size={layout.image_size}, "
              f"image_quality='{layout.image_quality}') observes them too, the same images after reset and each step")
    return f"The recovered env gives state observations only, not {keys}: {recipe}."


def _episode(arrays: dict[str, np.ndarray], attrs: dict[str, Any], env: Any, corrected: bool = False
             ) -> dict[str, Any]:
    """One demo as the fields of a `minari.EpisodeBuffer`; with `corrected`, the takeover labels in its infos
    (a demo recorded without takeover: intervention 0, the policy's action its own)."""
    keys = [path[len("obs/"):] for path in arrays if path.startswith("obs/")]
    observations = {k: np.concatenate([arrays[f"obs/{k}"], arrays[f"next_obs/{k}"][-1:]]) for k in keys}
    # The reset's info was not recorded; it is a function of the start state, which was.
    env.set_state(arrays["states"][0])
    _, info = env.observe()
    is_success = np.concatenate([[float(info["is_success"])], arrays["is_success"].astype(np.float64)])
    terminations = arrays["terminated"].astype(bool)
    truncations = arrays["truncated"].astype(bool)
    truncations[-1] |= not terminations[-1]
    meant = schema.meant_actions(arrays)
    expert_action = np.concatenate([np.full((1, meant.shape[1]), np.nan, np.float32), meant])
    infos = {"is_success": is_success, "expert_action": expert_action}
    if corrected:  # some demos corrected by a person (`--device takeover`); the reset's row: 0, NaN
        person = arrays.get("intervention", np.zeros(len(arrays["actions"]), np.uint8))
        proposed = arrays.get("policy_actions", arrays["actions"]).astype(np.float32)
        infos["intervention"] = np.concatenate([[0], person]).astype(np.uint8)
        infos["policy_action"] = np.concatenate([np.full((1, 4), np.nan, np.float32), proposed])
    return {"seed": int(attrs["seed"]), "observations": observations, "actions": arrays["actions"],
            "rewards": arrays["rewards"], "terminations": terminations, "truncations": truncations,
            "infos": infos}


def export_npz(ds_path: str | os.PathLike[str], out_dir: str | os.PathLike[str], *, demos: str = "successful",
               force: bool = False) -> Exported:
    """Write the selected demos as the seed collector's files in `out_dir`: `<env>_ep<NNNN>_<t>.npz`,
    numbered from 0 in the file's order, `t` the demo's end [s, Unix time], with collect_fetch_demo.py's keys.
    The files are written into a directory beside `out_dir` that replaces it whole once every file
    is there (`dirs.replacing_dir`): a kill at any instant leaves the old directory or the new one,
    never some of the files. A directory that is not empty is an error unless
    `force`, which replaces it."""
    import gymnasium as gym

    import fetch  # noqa: F401  (registers the ids)
    from fetch._durable import atomic_write
    from fetch._progress import progress

    out = pathlib.Path(out_dir)
    require_apart(out, [ds_path])
    with open_dataset(ds_path) as ds:
        require_valid(ds)  # nothing a tool flags as invalid is passed on
        chosen = select_demos(ds, demos)
        env = gym.make(ds.env_id, **ds.env_kwargs)
        base = {"env_id": ds.env_id, "max_steps": ds.settings.get("max_steps"),
                "action_space": str(env.action_space), "observation_space": str(env.observation_space),
                "exported_from": str(ds.path)}
        env.close()
        steps = 0
        with replacing_dir(out, force=force) as building:
            for index, name in enumerate(progress(chosen, len(chosen), "export")):
                demo = Demo(arrays=ds.arrays(name), attrs=chosen[name])
                ended = float(demo.attrs["ended"])
                metadata = {**npz.seed_metadata(base, demo, index, ended), "demo": name}
                path = building / f"{npz.file_stem(ds.env_id, index, ended)}.npz"
                content = npz.seed_file(demo, metadata)
                try:
                    atomic_write(path, content)
                except OSError as e:
                    raise DatasetError(f"cannot write {out / path.name}: {e}") from e
                steps += demo.num_samples
    return Exported(path=out, demos=tuple(chosen), steps=steps)


def export_lerobot(ds_path: str | os.PathLike[str], repo_id: str, out: str | os.PathLike[str] | None = None, *,
                   demos: str = "successful", cameras: list[str] | None = None, image_size: int | None = None,
                   image_quality: str | None = None, fps: float | None = None, workers: int | None = None,
                   force: bool = False) -> Exported:
    """Write the selected demos as the LeRobotDataset v3.0 `repo_id` in `out` (default: where LeRobot looks
    for it, $HF_LEROBOT_HOME/<repo_id>), with videos of `cameras` (default: the recorded ones, else front
    and wrist) at `image_size` (default: the recorded size, else 128) pixels, drawn at `image_quality` (default
    `lerobot.IMAGE_QUALITY`, as the LeRobot env draws unless told): the dataset's own images where it recorded
    those cameras at that size and quality, else rendered from the saved states."""
    from fetch.dataset.exports import lerobot, lerobot_writer
    from fetch.dataset.replay.render_obs import default_workers
    from fetch.rendering import check_image_quality

    lerobot.check_repo_id(repo_id)
    with open_dataset(ds_path) as ds:
        require_valid(ds)  # nothing a tool flags as invalid is passed on
        chosen = select_demos(ds, demos)
        cameras = list(ds.layout.cameras or ("front", "wrist")) if cameras is None else cameras
        image_size = image_size or ds.layout.image_size or 128
        quality = check_image_quality(image_quality or lerobot.IMAGE_QUALITY, "--image-quality")
        rate = lerobot.check_export(ds.env_id, ds.env_kwargs, cameras, image_size, fps)
        target = pathlib.Path(out) if out is not None else lerobot.lerobot_home() / repo_id
        require_apart(target, [ds_path])
        written = lerobot_writer.write_lerobot(ds, chosen, target, repo_id, cameras=cameras,
                                               image_size=image_size, image_quality=quality, fps=rate, force=force,
                                               workers=min(workers or default_workers(), len(chosen)))
    if not cameras:
        videos = ""
    elif written.stored_images:
        videos = f"the dataset's own {image_size} px {quality} images"
    else:
        videos = f"{image_size} px {quality} images drawn from the saved states"
    return Exported(path=written.path, demos=tuple(chosen), steps=written.frames, videos=videos)
