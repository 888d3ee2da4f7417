"""A run's checkpoint is a stranger's file: each field checked against the package's tables and the shapes its env
and policy kind give, before anything is built from it (`check`, which `checkpoint.read` calls)."""

from __future__ import annotations

import dataclasses
import json
import pathlib
import reprlib
from collections.abc import Mapping
from typing import Any, TypeGuard

import numpy as np
import torch

from fetch import observation as ob
from fetch.compiled import compiled_task
from fetch.env import recorded_kwargs
from fetch.errors import FetchError, one_line
from fetch.learn.data import flat_obs
from fetch.learn.kinds import PolicyConfig
from fetch.learn.policies import build
from fetch.learn.settings import MAX_TRAIN_STEPS, TrainConfig
from fetch.rendering import check_camera
from fetch.tasks import ENV_IDS, MAX_STEPS, registration
from fetch.tasks.base import Task

HISTORY = ("step", "train_loss", "valid_loss")
"""What a checkpoint's `history` holds: one number per checkpoint written, each."""
NORM_DTYPES = (torch.float32, torch.float64)
SEED_DTYPES = (torch.int64, torch.int32, torch.int16, torch.int8, torch.uint8)
SHOWN = 3
"""Weights named in a message about weights that do not fit."""


def check(file: pathlib.Path, state: Mapping[str, Any]) -> None:
    """FetchError (one line naming `file`) unless every field of the checkpoint `state` is one this version
    writes: its env a registered id with kwargs a file may set (`fetch.env.RECORDED_KWARGS`), its policy
    settings within their bounds (`fetch.learn.kinds`) and seeing its env's inputs, its weights those of
    the network the settings describe (compared on torch's meta device, so nothing is allocated), its
    normalisation of that many finite entries, its horizon and steps within the package's bounds."""
    try:
        _check(state)
    except FetchError as e:
        raise FetchError(f"{file}: {one_line(e)}") from e


def _check(state: Mapping[str, Any]) -> None:
    source = _mapping(state, "source")
    env_id = source.get("env_id")
    if not isinstance(env_id, str) or env_id not in ENV_IDS:
        raise FetchError(f"its env {reprlib.repr(env_id)} is not one of this package's: {', '.join(ENV_IDS)}")
    task = registration(env_id).task
    env_kwargs = source.get("env_kwargs")
    if not isinstance(env_kwargs, str):
        raise FetchError(f"its env_kwargs must be a JSON string, got {reprlib.repr(env_kwargs)}")
    try:
        recorded_kwargs(json.loads(env_kwargs))
    except (ValueError, RecursionError) as e:
        raise FetchError(f"its env_kwargs {reprlib.repr(env_kwargs)} are not JSON ({one_line(e)})") from e
    if not isinstance(source.get("dataset"), str) or not isinstance(source.get("train_demos"), list) \
            or not all(isinstance(n, str) for n in source["train_demos"]):
        raise FetchError("its source must name the dataset (a string) and its training demos (a list of names)")
    for name in ("policy", "train", "source"):
        _plain(name, _mapping(state, name))

    config = _policy(state["policy"])
    inputs = input_size(task, config.goal_offsets)
    if config.obs_size != inputs:
        offsets = " with goal offsets" if config.goal_offsets else ""
        raise FetchError(f"its policy sees {config.obs_size} inputs; a {env_id} policy{offsets} sees {inputs}")
    if config.cameras:
        model = compiled_task(task).model
        for camera in config.cameras:
            check_camera(model, camera)
    _fits(config, _mapping(state, "model"))
    _norm(config, _mapping(state, "norm"))

    if state.get("horizon") is not None:
        _whole("horizon", state["horizon"], 1, MAX_STEPS, " [steps], the most an episode is run")
    _whole("step", state["step"], 0, MAX_TRAIN_STEPS, ", the most steps a run takes")
    _train(_mapping(state, "train"))
    seeds = state["seeds"]
    if not _tensor(seeds) or seeds.dim() != 1 or seeds.dtype not in SEED_DTYPES:
        raise FetchError(f"its seeds must be a 1-D tensor of whole numbers, got {_described(seeds)}")
    rng = state["rng"]
    expected = torch.get_rng_state()
    if not _tensor(rng) or rng.dtype != expected.dtype or rng.shape != expected.shape:
        raise FetchError(f"its rng must be torch's generator state ({expected.dtype} {tuple(expected.shape)}), "
                         f"got {_described(rng)}")
    _mapping(state, "optimizer")  # its content is checked where a run resumes (`load_optimizer`)
    _history(_mapping(state, "history"))


def input_size(task: type[Task], goal_offsets: bool) -> int:
    """How many inputs a policy of `task` sees: its observation and goal, and with `goal_offsets` the goal's
    offsets too (`fetch.learn.data.flat_obs` on zeros of the task's observation's sizes)."""
    layout = ob.layout(task.parts)
    goal = layout[task.achieved]
    sizes = {"observation": sum(p.size for p in task.parts), "achieved_goal": goal.stop - goal.start,
             "desired_goal": goal.stop - goal.start}
    return int(flat_obs({k: np.zeros(n, np.float32) for k, n in sizes.items()}, goal_offsets).shape[-1])


def _mapping(state: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    value = state[name]
    if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
        raise FetchError(f"its {name} must be a mapping of names, got {_described(value)}")
    return value


def _plain(name: str, value: object) -> None:
    """FetchError unless `value` is plain values (JSON's), as every setting a run compares is."""
    try:
        json.dumps(value)
    except (TypeError, ValueError, RecursionError) as e:
        raise FetchError(f"its {name} must hold plain values only ({one_line(e)})") from e


def _whole(name: str, value: object, low: int, high: int, why: str) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise FetchError(f"its {name} must be a whole number from {low} to {high}{why}, got {reprlib.repr(value)}")


def _tensor(value: object) -> TypeGuard[torch.Tensor]:
    """Whether `value` is a plain dense tensor (not a parameter, nor sparse)."""
    return isinstance(value, torch.Tensor) and type(value) is torch.Tensor and value.layout == torch.strided


def _described(value: object) -> str:
    if isinstance(value, torch.Tensor):
        return f"a {value.dtype} tensor of shape {tuple(value.shape)}"
    return reprlib.repr(value)


def _policy(raw: Mapping[str, Any]) -> PolicyConfig:
    try:
        return PolicyConfig.from_dict(dict(raw))
    except (TypeError, ValueError) as e:  # a setting of a type the checks did not foresee
        raise FetchError(f"its policy settings are not ones this version reads ({one_line(e)})") from e


def _fits(config: PolicyConfig, weights: Mapping[str, Any]) -> None:
    """FetchError unless `weights` are those of the network `config` describes: that network is built on
    torch's meta device (shapes only, nothing allocated), so no setting can make `build` larger than the
    weights the file holds."""
    with torch.device("meta"):
        wanted = build(config).state_dict()
    wrong = [f"{k} missing" for k in wanted if k not in weights]
    wrong += [f"{reprlib.repr(k)} not one of its" for k in weights if k not in wanted]
    for k, v in weights.items():
        if k in wanted and (not isinstance(v, torch.Tensor) or v.layout != torch.strided or v.shape != wanted[k].shape
                            or v.is_floating_point() != wanted[k].is_floating_point()):
            wrong.append(f"{k} is {_described(v)}, not {tuple(wanted[k].shape)}")
    if wrong:
        more = f" and {len(wrong) - SHOWN} more" if len(wrong) > SHOWN else ""
        raise FetchError(f"its weights do not fit its policy settings ({config.kind}, hidden {config.hidden}, layers "
                         f"{config.layers}, members {config.members}): {'; '.join(wrong[:SHOWN])}{more}")


def _norm(config: PolicyConfig, norm: Mapping[str, Any]) -> None:
    for name in ("mean", "std"):
        value = norm.get(name)
        if not (_tensor(value) and value.dtype in NORM_DTYPES and value.shape == (config.obs_size,)):
            raise FetchError(f"its norm {name} must be a float tensor of shape ({config.obs_size},), one entry per "
                             f"input, got {_described(value)}")
        if not bool(torch.isfinite(value).all()):
            raise FetchError(f"its norm {name} holds NaN or infinite entries")
    if not bool((norm["std"] > 0).all()):
        raise FetchError("its norm std must be above 0 everywhere (the inputs are divided by it)")


def _train(raw: Mapping[str, Any]) -> None:
    known = {f.name for f in dataclasses.fields(TrainConfig)}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise FetchError(f"unknown training settings {reprlib.repr(unknown)}; known: {', '.join(sorted(known))}")
    try:
        TrainConfig(**{**dataclasses.asdict(TrainConfig()), **raw})
    except FetchError as e:
        raise FetchError(f"its training settings: {e}") from e


def _history(history: Mapping[str, Any]) -> None:
    lists = [v for v in history.values() if isinstance(v, list)]
    if set(history) != set(HISTORY) or len(lists) != len(HISTORY) or len({len(v) for v in lists}) > 1 \
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for v in lists for x in v):
        raise FetchError(f"its history must be {', '.join(HISTORY)}: lists of numbers, one per checkpoint")


def load_weights(file: pathlib.Path, model: torch.nn.Module, weights: Mapping[str, Any]) -> None:
    """`model.load_state_dict(weights)`; a one-line FetchError naming `file` when they do not fit."""
    try:
        model.load_state_dict(weights)
    except (RuntimeError, ValueError, TypeError, KeyError) as e:
        raise FetchError(f"{file}: its weights do not fit its policy settings ({one_line(e)})") from e


def load_optimizer(file: pathlib.Path, optimizer: torch.optim.Optimizer, saved: dict[str, Any]) -> None:
    """Resume `optimizer` from its state `saved` in `file`: the same settings as the run's (but the learning rate,
    which is set every step), and state tensors of its parameters' shapes; else a one-line FetchError."""
    fresh = [{k: v for k, v in group.items() if k not in ("params", "lr")} for group in optimizer.param_groups]
    try:
        optimizer.load_state_dict(saved)
    except (RuntimeError, ValueError, TypeError, KeyError, IndexError) as e:
        raise FetchError(f"{file}: its optimizer state does not fit its policy ({one_line(e)})") from e
    for group, settings in zip(optimizer.param_groups, fresh, strict=True):
        changed = sorted(k for k, v in settings.items() if not _same(group.get(k), v))
        if changed:
            raise FetchError(f"{file}: its optimizer's {', '.join(changed)} are not the run's")
        for p in group["params"]:
            for name, value in optimizer.state[p].items():
                if not isinstance(value, torch.Tensor) or not value.is_floating_point() \
                        or value.shape not in (torch.Size(()), p.shape):
                    raise FetchError(f"{file}: its optimizer's {name} is {_described(value)}, not of its weights' "
                                     f"shape {tuple(p.shape)}")


def _same(loaded: object, setting: object) -> bool:
    """Whether an optimizer setting read from a file is the run's: of its type and equal to it."""
    try:
        return type(loaded) is type(setting) and bool(loaded == setting)
    except (RuntimeError, TypeError, ValueError):  # a tensor where a number should be, say
        return False
