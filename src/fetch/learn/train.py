"""Training a policy on a dataset: deterministic under a seed, resumable from an atomic checkpoint."""

from __future__ import annotations

import ctypes
import dataclasses
import io
import json
import math
import os
import pathlib
import sys
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import torch

from fetch.errors import FetchError
from fetch.learn import checkpoint as ckpt
from fetch.learn.checked import load_optimizer, load_weights
from fetch.learn.data import Demos, Normalizer, load_demos, policy_inputs, with_reflections
from fetch.learn.kinds import PolicyConfig
from fetch.learn.policies import Samples, behaviour_loss, build, implementation, samples
from fetch.learn.settings import ACCELERATORS, TrainConfig, TrainPlan, TrainRequest, plan, sees_pixels


@dataclasses.dataclass(frozen=True)
class TrainResult:
    """What a finished run reports: where it is, its steps, and its last losses (None: no valid split)."""

    run: pathlib.Path
    steps: int
    train_loss: float
    valid_loss: float | None
    resumed_from: int
    plan: TrainPlan
    """what was trained: the policy's settings and the training's."""


def learning_rate(config: TrainConfig, step: int) -> float:
    return config.lr * 0.5 * (1.0 + math.cos(math.pi * step / config.steps))


def batch_indices(config: TrainConfig, count: int, step: int) -> np.ndarray:
    """The examples of gradient step `step`: epoch e is a permutation drawn from (seed, e), so any
    step's batch follows from the step alone and a resumed run draws what an uninterrupted one would."""
    size = min(config.batch_size, count)
    per_epoch = count // size
    epoch, index = divmod(step, per_epoch)
    order = np.random.default_rng([config.seed, epoch]).permutation(count)
    return order[index * size:(index + 1) * size]


CPU = torch.device("cpu")


def accelerator(asked: str = "auto") -> torch.device:
    """Where training runs: CUDA when asked for, or when present and `asked` is "auto"; else the CPU."""
    if asked not in ACCELERATORS:
        raise FetchError(f"--accelerator {asked!r}: choose one of {', '.join(ACCELERATORS)}")
    if asked == "cuda" and not torch.cuda.is_available():
        raise FetchError("--accelerator cuda: torch sees no CUDA device here (torch.cuda.is_available() is False)")
    if asked == "cpu" or not torch.cuda.is_available():
        return CPU
    # cuBLAS is deterministic only with this workspace setting (PyTorch's reproducibility notes).
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    return torch.device("cuda")


def native_bf16(device: torch.device) -> bool:
    """Whether `device` computes bfloat16 natively (else autocast's bf16 is emulated, and slower)."""
    if device.type == "cuda":
        return bool(torch.cuda.is_bf16_supported())
    cpu: Any = getattr(torch, "cpu", None)
    return any(bool(getattr(cpu, probe, lambda: False)()) for probe in ("_is_avx512_bf16_supported",
                                                                         "_is_amx_tile_supported"))


MALLOC_HELD = (-3, 32 << 20), (-1, 1 << 30)
"""glibc `mallopt` settings while training: blocks up to 32 MiB come from the heap (M_MMAP_THRESHOLD, -3), and
up to 1 GiB that the heap frees stays with the process (M_TRIM_THRESHOLD, -1)."""


def hold_freed_memory() -> bool:
    """Have glibc's malloc keep the memory a training step frees for the next step. A pixel step allocates
    and frees tens of MB of activations; by default glibc returned them to the kernel (freed blocks over
    its threshold are unmapped, the heap's top is trimmed) and took them back, zeroed page by page, the
    next step: a third of a step's time went to the kernel, and a step on two AVX2 cores took 240 against
    191 ms (`python -m benchmarks.pixel_step`). Process-wide and for the rest of the process (glibc cannot
    go back to its adaptive default): it keeps up to 1 GiB more than it would. False where there is no
    glibc (macOS, musl's mallopt does nothing)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return all(mallopt(option, value) == 1 for option, value in MALLOC_HELD)


VALID_IMAGE_EXAMPLES = 2048
"""A pixel policy's validation loss is measured on at most this many validation examples, evenly spaced
through them: all of the Bin-place mission's 8200 took 9 s at each of its six checkpoints on 2 cores."""


def validation_loss(policy: PolicyConfig, model: torch.nn.Module, valid: Samples | None,
                    device: torch.device = CPU) -> float | None:
    """The behaviour-cloning loss on the validation demos (whatever else the kind's loss adds); a pixel
    policy's on `VALID_IMAGE_EXAMPLES` of them at most."""
    if valid is None or len(valid) == 0:
        return None
    batch = valid.tensors()
    if batch.images and len(valid) > VALID_IMAGE_EXAMPLES:
        batch = batch.take(torch.linspace(0, len(valid) - 1, VALID_IMAGE_EXAMPLES).round().long())
    size = 512 if batch.images else 4096  # a pixel policy's activations are large
    model.eval()
    with torch.no_grad():
        total = sum(float(behaviour_loss(policy, model, part.to(device))) * float(part.m.sum())
                    for part in (batch.take(slice(i, i + size)) for i in range(0, len(batch.x), size)))
    model.train()
    return total / float(batch.m.sum())


@dataclasses.dataclass(frozen=True)
class RunPlan:
    """What a run trains, resolved before anything is trained: its settings, its policy and its demos."""

    chosen: TrainPlan
    """the settings, precision resolved for `device`."""
    policy: PolicyConfig
    """the network, with its input sizes."""
    demos: Demos
    """the demos it learns from: those asked for (`--demos`) and, mirrored, their mirror images."""
    source: dict[str, Any]
    """where the demos (and, going on from a run, the weights) came from: the checkpoint's "source"."""
    horizon: int
    """[steps] the episode length a policy learnt from these demos is given (`Demos.horizon`, before mirroring)."""
    device: torch.device
    base: dict[str, Any] | None
    """the checkpoint of the run it goes on from (`TrainPlan.start_from`), or None."""


class RunState(NamedTuple):
    """Where the gradient steps start: a new network or the one a checkpoint holds, and what it saved."""

    model: torch.nn.Module
    optimizer: torch.optim.Optimizer
    norm: Normalizer
    history: dict[str, list[float]]
    """per checkpoint: its step, the mean training loss since the one before, the validation loss (nan: none)."""
    start: int
    """the gradient steps already taken (0: a new run)."""


def plan_run(dataset: str | os.PathLike[str] | Demos, run: pathlib.Path,
             request: TrainRequest | TrainPlan) -> RunPlan:
    """What `train` trains in `run`: the demos loaded (with images for a pixel policy), checked against the
    run it goes on from, cut to `--demos` and mirrored; the settings `settings.plan` fills in; the policy's
    input sizes; the device and the precision it computes in."""
    start_from = request.start_from
    base = ckpt.read(start_from) if start_from is not None else None
    demos = dataset if isinstance(dataset, Demos) else load_demos(dataset, images=sees_pixels(request, base))
    for origin in demos.origins or (demos.origin,):
        ckpt.require_outside(run, pathlib.Path(origin))
    if base is not None and base["source"]["env_id"] != demos.env_id:
        raise FetchError(f"--from {start_from} is a {base['source']['env_id']} policy; these demos are {demos.env_id}")
    chosen = plan(request, demos, base) if isinstance(request, TrainRequest) else request
    if chosen.policy.cameras and any(c not in e.images for e in demos.train[:1] for c in chosen.policy.cameras):
        raise FetchError(f"a pixel policy learns from the demos' images: load them with images "
                         f"(fetch.learn.data.load_demos(path, images=True)); {demos.origin} was loaded without")
    config = chosen.config
    if config.demos:
        if len(demos.train) < config.demos:
            raise FetchError(f"--demos {config.demos}: {demos.origin} has only {len(demos.train)} demos in mask/train")
        demos = dataclasses.replace(demos, train=demos.train[:config.demos])
    source: dict[str, Any] = {"dataset": demos.origin, "env_id": demos.env_id,
              "env_kwargs": json.dumps(demos.env_kwargs, sort_keys=True),
              "train_demos": [e.name for e in demos.train]}
    if base is not None:
        source["from"] = {"run": str(pathlib.Path(str(start_from)).resolve()), "step": int(base["step"])}
    horizon = demos.horizon
    if config.mirror:
        demos = with_reflections(demos)
    pixels = bool(chosen.policy.cameras)
    policy_config = PolicyConfig(**chosen.policy.as_dict(),
                                 obs_size=policy_inputs(demos.train[0], chosen.policy.goal_offsets).shape[1],
                                 image_size=demos.image_size if pixels else 0,
                                 image_quality=demos.image_quality if pixels else "")
    device = accelerator(request.accelerator if isinstance(request, TrainRequest) else "auto")
    if chosen.config.precision == "auto":
        chosen = dataclasses.replace(chosen, config=dataclasses.replace(
            chosen.config, precision="bf16" if native_bf16(device) else "fp32"))
    return RunPlan(chosen, policy_config, demos, source, horizon, device, base)


def restore(planned: RunPlan, run: pathlib.Path, say: Callable[[str], object]) -> RunState:
    """The network, optimizer and normalisation the gradient steps start from: new ones under the seed, with
    the weights and normalisation of the run it goes on from (`--from`), and, where `run` already holds a
    checkpoint of the same settings, everything that checkpoint saved (its generator's state included), so
    the steps go on as if never stopped. Sets torch's threads and determinism for the process."""
    config, policy_config, demos, base = planned.chosen.config, planned.policy, planned.demos, planned.base
    start_from = planned.chosen.start_from
    torch.set_num_threads(config.threads)
    hold_freed_memory()
    torch.use_deterministic_algorithms(True)
    torch.manual_seed(config.seed)
    norm = Normalizer.fit(demos.train, policy_config.goal_offsets, policy_config.blind)
    model = build(policy_config)
    if base is not None:
        learnt = PolicyConfig.upgraded(base["policy"])
        if policy_config.cameras and (learnt["image_size"], learnt["image_quality"]) != (demos.image_size,
                                                                                          demos.image_quality):
            raise FetchError(f"--from {start_from} learnt from {learnt['image_size']} px {learnt['image_quality']}-"
                             f"quality images; {demos.origin} holds {demos.image_size} px {demos.image_quality}")
        if ckpt.plain(learnt) != ckpt.plain(policy_config.as_dict()):
            raise FetchError(f"--from {start_from}: its policy has other settings than the ones asked for; leave "
                             "the policy flags out and the run's are used")
        load_weights(ckpt.file_of(str(start_from)), model, base["model"])
        norm = Normalizer(base["norm"]["mean"].numpy(), base["norm"]["std"].numpy())
    model.to(planned.device)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    history: dict[str, list[float]] = {"step": [], "train_loss": [], "valid_loss": []}
    start = 0
    previous = ckpt.read(run) if ckpt.path(run).exists() else None
    if previous is not None:
        # A run saved before a training setting existed had that setting's default.
        saved = {**dataclasses.asdict(TrainConfig()), **previous["train"]}
        ckpt.require_same(run, {**previous, "train": saved, "policy": PolicyConfig.upgraded(previous["policy"])},
                          policy_config.as_dict(), dataclasses.asdict(config), planned.source)
        load_weights(ckpt.path(run), model, previous["model"])
        load_optimizer(ckpt.path(run), optimizer, previous["optimizer"])
        torch.set_rng_state(previous["rng"])
        history = {k: list(v) for k, v in previous["history"].items()}
        start = int(previous["step"])
        if start < config.steps:
            say(f"resuming {run} from step {start} of {config.steps}")
    else:
        run.mkdir(parents=True, exist_ok=True)
    return RunState(model, optimizer, norm, history, start)


def loop(planned: RunPlan, state: RunState, run: pathlib.Path, say: Callable[[str], object],
         show_progress: bool = True) -> TrainResult:
    """The gradient steps from `state.start` to the plan's last: each step's learning rate and batch follow
    from the step alone; every `checkpoint_every` steps and at the last, the validation loss is measured and
    the whole state written to `run`'s checkpoint atomically, so a run stopped at any moment (even killed)
    resumes from the last one as if never stopped."""
    from fetch._progress import progress

    chosen, config, policy_config, demos = planned.chosen, planned.chosen.config, planned.policy, planned.demos
    device, (model, optimizer, norm, history, start) = planned.device, state
    train_samples = samples(policy_config, demos.train, norm)
    valid_samples = samples(policy_config, demos.valid, norm) if demos.valid else None
    examples = train_samples.tensors()
    loss_of = implementation(policy_config.kind).loss
    running: list[float] = []
    members = f" x{policy_config.members}" if policy_config.members > 1 else ""
    mirrored = ", mirror images included" if config.mirror else ""
    mirrored += f", seeing {', '.join(policy_config.cameras)}" if policy_config.cameras else ""
    where = (f" on {device}" if device != CPU else "") + (" in bf16" if config.precision == "bf16" else "")
    say(f"training {policy_config.kind}{members} on {len(demos.train)} {demos.env_id} demos{mirrored} "
        f"({len(train_samples)} examples) for steps {start + 1}-{config.steps}, batch {config.batch_size}, "
        f"{config.threads} thread(s){where}; horizon {planned.horizon} steps; checkpoint every "
        f"{config.checkpoint_every} steps in {ckpt.path(run)}")
    clock = time.perf_counter()
    first = min(config.steps, start + max(10, (config.steps - start) // 100))  # when to say how long it takes

    def save(step: int) -> None:
        saved = {"format": ckpt.FORMAT, "version": ckpt.VERSION, "policy": policy_config.as_dict(),
                 "train": dataclasses.asdict(config), "source": planned.source, "step": step,
                 "norm": {"mean": torch.from_numpy(norm.mean), "std": torch.from_numpy(norm.std)},
                 "seeds": torch.tensor(sorted(demos.seeds), dtype=torch.int64),
                 "model": model.state_dict(), "optimizer": optimizer.state_dict(), "rng": torch.get_rng_state(),
                 "history": history, "horizon": planned.horizon}
        buffer = io.BytesIO()
        torch.save(saved, buffer)
        ckpt.write(run, buffer.getvalue())

    steps = range(start, config.steps)
    for step in progress(steps, len(steps), f"train {policy_config.kind}", "steps") if show_progress else steps:
        for group in optimizer.param_groups:
            group["lr"] = learning_rate(config, step)
        batch = examples.take(torch.from_numpy(batch_indices(config, len(train_samples), step)))
        if config.obs_noise:  # drawn on the CPU, whose generator the checkpoint keeps, on any device
            batch = batch._replace(x=batch.x + config.obs_noise * torch.randn_like(batch.x))
        batch = batch.to(device)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=config.precision == "bf16"):
            loss = loss_of(policy_config, model, batch)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        running.append(float(loss.detach()))
        done = step + 1
        if done == first and done < config.steps:
            rate = (done - start) / max(time.perf_counter() - clock, 1e-9)
            say(f"step {done}/{config.steps}: {rate:.0f} steps/s, about {(config.steps - done) / rate / 60:.1f} "
                "minutes to go")
        if done % config.checkpoint_every == 0 or done == config.steps:
            valid = validation_loss(policy_config, model, valid_samples, device)
            history["step"].append(float(done))
            history["train_loss"].append(float(np.mean(running)))
            history["valid_loss"].append(math.nan if valid is None else valid)
            running = []
            save(done)
            if not show_progress or not sys.stderr.isatty():
                shown = "none (no valid split)" if valid is None else f"{valid:.4f}"
                say(f"step {done}/{config.steps}: train loss {history['train_loss'][-1]:.4f}, valid loss {shown}")
    if not history["step"]:  # steps was 0 left to do and nothing had been saved: cannot happen after a save
        raise FetchError(f"{run}: no training step was taken")
    last_valid = history["valid_loss"][-1]
    return TrainResult(run, config.steps, history["train_loss"][-1],
                       None if math.isnan(last_valid) else last_valid, start, chosen)


def train(dataset: str | os.PathLike[str] | Demos, out: str | os.PathLike[str],
          request: TrainRequest | TrainPlan | None = None, *, log: Any = None,
          show_progress: bool = True) -> TrainResult:
    """Train a policy on `dataset`, writing `out/checkpoint.pt`, as `gym-fetch train` does.

    `dataset` is a dataset file or directory, or demos already loaded (and, say, relabelled). `request`
    says what to train, with the same defaults as the command (`settings.plan` fills them in; None: all
    of them); a `TrainPlan` is trained as it is. A run that `out` already holds with the same settings is
    resumed from its last checkpoint (one that finished is left as it is). Going on from another run
    (`start_from`, `gym-fetch train --from`) starts from its weights and its input normalisation, so
    what it learnt still applies, and keeps its policy settings."""
    say = log if log is not None else (lambda line: print(line, file=sys.stderr, flush=True))
    run = pathlib.Path(out)
    planned = plan_run(dataset, run, TrainRequest() if request is None else request)
    return loop(planned, restore(planned, run, say), run, say, show_progress)
