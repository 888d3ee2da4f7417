"""Validating a dataset: every inconsistency a tool must not pass on (`validate`, what `gym-fetch info`
lists), and the check every tool makes before it uses a file (`require_valid`)."""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

import h5py
import numpy as np

from fetch._durable import journal_of
from fetch.dataset import schema
from fetch.dataset.reader import READ_ERRORS, Dataset, one_line, plain_value
from fetch.errors import DatasetError
from fetch.tasks.base import goal_distance, reward


def header_problems(ds: Dataset) -> list[str]:
    """What is wrong with the dataset's description of its env and model: an env id that is not
    registered, `env_kwargs` the env refuses, a state size other than the env's, a `model_xml` that
    is not MJCF. Each tool checks these before it uses the file (`require_valid`)."""
    import gymnasium as gym
    import mujoco

    import fetch

    problems = []
    if ds.env_id not in fetch.ENV_IDS:
        problems.append(f"data.attrs['env_args'] names the env {ds.env_id!r}, which is not one of gym-fetch-v2's: "
                        f"{', '.join(fetch.ENV_IDS)}")
    else:
        try:
            env: Any = gym.make(ds.env_id, **ds.env_kwargs)
        except Exception as e:  # noqa: BLE001 (the env's own check of its arguments, whatever it raises)
            problems.append(f"data.attrs['env_args'] has env_kwargs {ds.env_kwargs!r}, which {ds.env_id} refuses: "
                            f"{one_line(e)}")
        else:
            state_size = int(np.asarray(env.unwrapped.get_state()).size)
            here = env.unwrapped.model_xml()
            names = _element_names(here)
            same_model = ds.data_attrs.get("model_hash") in (env.unwrapped.model_hash(),
                                                               env.unwrapped.legacy_model_hash())
            env.close()
            if state_size != ds.layout.state_size:
                problems.append(f"data.attrs['layout'] has state_size {ds.layout.state_size}, but {ds.env_id} "
                                f"states have {state_size} values")
            recorded = _element_names(ds.data_attrs.get("model_xml"))
            if same_model and recorded is not None and _portable(ds.data_attrs["model_xml"]) != _portable(here):
                problems.append(f"data.attrs['model_xml'] is not the model data.attrs['model_hash'] names (this "
                                f"install's {ds.env_id} model)")
            elif recorded is not None and names is not None and recorded != names:
                other = sorted((recorded - names) | (names - recorded))
                problems.append(f"data.attrs['model_xml'] is not a model of {ds.env_id}: it names other bodies, "
                                f"joints or sites ({', '.join(other[:4])}{' ...' if len(other) > 4 else ''})")
    for key, kind in schema.DATA_ATTR_KINDS.items():
        if key in ds.data_attrs or key == "total":
            problem = schema.kind_problem(ds.data_attrs.get(key), kind)
            problems += [] if problem is None else [f"data.attrs['{key}'] {problem}"]
    digest = ds.data_attrs.get("model_hash")
    if not (isinstance(digest, str) and len(digest) == 64 and all(c in "0123456789abcdef" for c in digest)):
        problems.append(f"data.attrs['model_hash'] is {digest!r}, not a SHA-256 (64 hexadecimal digits)")
    xml = ds.data_attrs.get("model_xml")
    try:
        mujoco.MjSpec.from_string(xml)  # parsed, not compiled: the meshes' directory is the recording machine's
    except Exception as e:  # noqa: BLE001 (mujoco raises ValueError or TypeError, by version)
        problems.append(f"data.attrs['model_xml'] is not the model's MJCF (corrupt or missing: {one_line(e)[:200]})")
    return problems


def _portable(xml: str) -> str:
    """MJCF without the install's asset directories (the same model installed elsewhere names others)."""
    return re.sub(r' (?:meshdir|texturedir)="[^"]*"', "", xml)


def _element_names(xml: Any) -> frozenset[str] | None:
    """The named bodies, joints and sites of an MJCF model (what tells one task's scene from another's);
    None if it does not parse (`header_problems` says so)."""
    import mujoco

    try:
        spec = mujoco.MjSpec.from_string(xml)
    except Exception:  # noqa: BLE001 (mujoco raises ValueError or TypeError, by version)
        return None
    elements = [*spec.bodies, *spec.joints, *spec.sites]
    return frozenset(f"{type(e).__name__[3:].lower()} {e.name}" for e in elements if e.name)


Keep = Callable[[str], bool]
"""Which of a demo's camera images (by path in the demo group) a pass over the file reads for its caller."""
Visit = Callable[[str, dict[str, Any], dict[str, np.ndarray]], None]
"""Called with a sound demo's name, attributes and arrays (every array but the images `Keep` leaves out)."""


def _demo_problems(ds: Dataset, name: str, images: bool = True, keep: Keep | None = None,
                   visit: Visit | None = None) -> tuple[list[str], int | None, dict[str, Any]]:
    """What is wrong with one demo (each problem starts with its name), its steps if they are known and its
    attributes (empty where unreadable). With `visit`, a demo without problems is handed to it, read once
    for both: every array, but of the camera images only those `keep` takes."""
    try:
        group = ds.demo(name)
    except DatasetError as e:
        return [str(e)], None, {}
    try:
        attrs = {k: plain_value(v) for k, v in group.attrs.items()}
        attr_problems = schema.check_demo_attrs(attrs)
        if attr_problems:
            return [f"{name}: {p}" for p in attr_problems], None, {}
        t = int(attrs["num_samples"])
        nodes: dict[str, h5py.Dataset] = {}

        def found(path: str, node: Any, into: dict[str, Any] = nodes) -> None:
            if isinstance(node, h5py.Dataset):
                into[path] = node

        group.visititems(found)
        # Checked as read (a numpy array's [()] is itself); images stay on disk unless the caller wants them.
        arrays: dict[str, Any] = {p: node if schema.is_image(p) and (visit is None or keep is None or not keep(p))
                                  else node[()] for p, node in nodes.items()}
        problems = _content_problems(ds, name, attrs, arrays, t, images)
    except READ_ERRORS as e:
        try:
            file, _ = ds.demo_file(name)
        except READ_ERRORS:
            file = ds.path
        where = file.relative_to(ds.path.parent) if file.is_relative_to(ds.path.parent) else file
        return [f"{name} cannot be read (its file {where} is corrupt: {one_line(e)})"], None, {}
    if visit is not None and not problems:  # outside the reading's `try`: the visitor's own errors are its own
        visit(name, attrs, {p: a for p, a in arrays.items() if isinstance(a, np.ndarray)})
    return problems, t, attrs


def _content_problems(ds: Dataset, name: str, attrs: dict[str, Any], arrays: dict[str, Any], t: int,
                      images: bool) -> list[str]:
    layout = ds.layout
    shape_problems = schema.check_arrays(arrays, layout, t)
    missing_images = {f"missing {p}/{schema.image_key(c)}" for c in layout.cameras for p in ("obs", "next_obs")}
    if not images:
        shape_problems = [p for p in shape_problems if p not in missing_images]
    elif shape_problems and set(shape_problems) <= missing_images:
        return [f"{name}: its images are not rendered yet (the collector stopped first): run "
                "`gym-fetch collect` on this directory again, or `gym-fetch render-obs --overwrite`"]
    if shape_problems:
        return [f"{name}: {p}" for p in shape_problems]
    problems = []
    actions = arrays["actions"][()]
    if not np.all(np.isfinite(actions)):
        problems.append(f"{name}: actions hold NaN or infinite values")
    elif t and np.abs(actions).max() > 1.0:
        problems.append(f"{name}: actions outside [-1, 1] (robomimic rejects them)")
    for key, _ in layout.obs_sizes:
        obs, nxt = arrays[f"obs/{key}"][()], arrays[f"next_obs/{key}"][()]
        if not (np.all(np.isfinite(obs)) and np.all(np.isfinite(nxt))):
            problems.append(f"{name}: obs/{key} or next_obs/{key} hold NaN or infinite values")
        elif t > 1 and not np.array_equal(obs[1:], nxt[:-1]):
            problems.append(f"{name}: next_obs/{key}[t] differs from obs/{key}[t+1]")
    if "expert_actions" in arrays:  # what training learns, where present
        meant = arrays["expert_actions"][()]
        if meant.shape != actions.shape or not np.all(np.isfinite(meant)) or (t and np.abs(meant).max() > 1.0):
            problems.append(f"{name}: expert_actions must be {actions.shape}, finite and within [-1, 1]")
    if "intervention" in arrays and not np.isin(arrays["intervention"][()], (0, 1)).all():
        problems.append(f"{name}: intervention holds values other than 0 (the policy drove) and 1 (a person)")
    if "policy_actions" in arrays:
        proposed = arrays["policy_actions"][()]
        if not np.all(np.isfinite(proposed)) or (t and np.abs(proposed).max() > 1.0):
            problems.append(f"{name}: policy_actions must be finite and within [-1, 1]")
    if ("intervention" in arrays) != ("policy_actions" in arrays):
        problems.append(f"{name}: intervention and policy_actions come together (a takeover session records both)")
    rewards = arrays["rewards"][()]
    success_known = np.isin(arrays["is_success"][()], (0, 1)).all()
    if not success_known:
        problems.append(f"{name}: is_success holds values other than 0 and 1")
    if not np.all(np.isfinite(rewards)):
        problems.append(f"{name}: rewards hold NaN or infinite values")
    elif t and success_known and (wrong := _reward_problem(ds, arrays, rewards)):
        problems.append(f"{name}: {wrong}")
    if t and np.asarray(arrays["terminated"][()])[:-1].any():
        problems.append(f"{name}: terminated before its last step (an episode ends where it terminates)")
    if not np.all(np.isfinite(arrays["states"][()])):
        problems.append(f"{name}: states hold NaN or infinite values")
    dones = arrays["dones"][()]
    if t and (dones[-1] != 1 or dones[:-1].any()):
        problems.append(f"{name}: dones must be 1 at the last step only")
    if bool(attrs["success"]) and t and not arrays["is_success"][()].any():
        problems.append(f"{name}: marked successful but is_success is never 1")
    if str(attrs["env_id"]) != ds.env_id:
        problems.append(f"{name}: env_id {attrs['env_id']!r} differs from the dataset's {ds.env_id!r}")
    return problems


def _reward_problem(ds: Dataset, arrays: dict[str, h5py.Dataset], rewards: np.ndarray) -> str | None:
    """Why the rewards are not the env's for the steps recorded (`fetch.tasks.base.reward` of each step's
    success and goal distance after it, as `FetchEnv.step` gives them), or None."""
    reward_type = ds.env_kwargs.get("reward_type", "sparse")
    success = np.asarray(arrays["is_success"][()], np.float64)
    distance = goal_distance(arrays["next_obs/achieved_goal"][()], arrays["next_obs/desired_goal"][()])
    expected = reward(reward_type, success, distance)
    # Sparse rewards are exact; a dense one is math.dist's, which differs from numpy's in the last bit.
    exact = np.array_equal(rewards, expected) if reward_type == "sparse" else \
        bool(np.allclose(rewards, expected, rtol=0.0, atol=1e-9))
    if exact:
        return None
    step = int(np.flatnonzero(~np.isclose(rewards, expected, rtol=0.0, atol=1e-9))[0])
    return (f"rewards[{step}] is {rewards[step]:.6g}, but a {reward_type} reward there is {expected[step]:.6g} "
            f"(env_kwargs reward_type {reward_type!r})")


def validate(ds: Dataset, keep: Keep | None = None, visit: Visit | None = None) -> list[str]:
    """Every inconsistency found in the file (empty when it is sound); each names the demo and key. With
    `visit`, each sound demo is handed to it as it is checked, read once for both (`_demo_problems`): a
    loader that checks a whole file reads it once."""
    problems = header_problems(ds)
    if journal_of(ds.path).exists():
        problems.append(f"an edit (render-obs, split) was stopped while it replaced the files, some old and some "
                        f"new ({journal_of(ds.path).name} lists them): open it once with write access and no "
                        "collector running (e.g. `gym-fetch info`), which finishes the edit")
    try:
        problems += [f"data/{name}: not a demo name (demo_<integer>)" for name in ds.file["data"].keys()
                     if not _is_demo_name(name)]
    except READ_ERRORS as e:
        problems.append(f"the list of demos cannot be read (the file is corrupt: {one_line(e)})")
    total = 0
    success: dict[str, bool] = {}  # of each readable demo
    for name in ds.demo_names:
        found, t, attrs = _demo_problems(ds, name, keep=keep, visit=visit)
        problems += found
        if t is not None:
            total += t
            success[name] = bool(attrs["success"])
    unreadable = set(ds.demo_names) - set(success)
    recorded = ds.data_attrs.get("total")
    if not unreadable and isinstance(recorded, int) and recorded != total:
        problems.append(f"data.attrs['total'] is {ds.data_attrs.get('total')}, the demos hold {total} steps")
    try:
        masks = ds.masks()
    except DatasetError as e:
        return [*problems, str(e)]
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
            if n in success and success[n] != (key != "failed"):
                problems.append(f"{n} is in mask/{key} but its success is {success[n]}")
    return problems


def _is_demo_name(name: str) -> bool:
    try:
        schema.demo_index(name)
    except ValueError:
        return False
    return True


def require_valid(ds: Dataset, names: list[str] | None = None, *, images: bool = True, keep: Keep | None = None,
                  visit: Visit | None = None) -> None:
    """What every tool does before it uses a dataset: DatasetError, one line naming the file and its
    first problem, unless the file is sound. `names`: only these demos (and the file's header and
    masks) must be; None: the whole file, as `gym-fetch info` validates it. `images=False`: demos
    whose camera images are not rendered yet pass (replay and render-obs do not read them). `visit`
    (with `keep`): each sound demo is handed to it as read for the check (`validate`); the error comes
    after the whole pass."""
    if names is None:
        problems = validate(ds, keep, visit)
    else:
        problems = header_problems(ds)
        try:
            ds.masks()
        except DatasetError as e:
            problems.append(str(e))
        for name in names:
            problems += _demo_problems(ds, name, images, keep, visit)[0]
    if problems:
        first = one_line(problems[0])
        first = first if first.startswith(str(ds.path)) else f"{ds.path}: {first}"
        more = f" (and {len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
        raise DatasetError(f"{first}{more}; `gym-fetch info {ds.path}` lists what is wrong")
