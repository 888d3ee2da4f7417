"""One training step of the pixel policy (`cnn-chunk`): the images' memory layout and malloc's settings.

    python -m benchmarks.pixel_step [--batch-size 64] [--image-size 64] [--cameras front,wrist]
        [--steps 10] [--rounds 4] [--threads N] [--precision fp32|bf16|auto]

What `gym-fetch train --inputs pixels` does per step, on made-up images and targets of the mission's shapes
(a batch of 64 examples, two cameras at 64 x 64 (`--image-size`), Bin-place's 25-entry input): the random shift, both
encoders, the heads, the loss with the unseen-state guess, backward and Adam, under `torch.autocast` in
bf16 where `--precision` says so (auto: bf16 where the CPU computes it natively, as `train` decides).
The layouts:

- NHWC (`PixelChunk.memory_format`, torch's channels_last): the encoders' weights and the shifted images
  laid out with the colour channels innermost, as the images come;
- NCHW: torch's default layout, which `train` used until 2026-11-27;

each with glibc's malloc as `train` sets it (`fetch.learn.train.hold_freed_memory`: freed memory kept for
the next step) and as it is by default (freed activations handed back to the kernel and faulted in again).
malloc's setting holds for a whole process, so each round runs one process per setting, which times
`--steps` steps of every layout after two untimed ones (oneDNN picks its kernels); the CPU time the process
spent in the kernel is given beside. A figure is the median over the rounds, a ratio the median of the
within-round ratios, so that a machine whose speed drifts (a shared VM) disturbs the comparison less than
the figures. Run from the repository root.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import torch

from benchmarks._machine import machine
from fetch.camera_obs import DEFAULT_IMAGE_SIZE
from fetch.learn.kinds import PolicyConfig
from fetch.learn.pixels import PixelChunk, pixel_loss
from fetch.learn.policies import ACTION_SIZE, Batch
from fetch.learn.train import hold_freed_memory, native_bf16

LAYOUTS = {"NHWC (channels_last, now)": torch.channels_last, "NCHW (before)": torch.contiguous_format}
MALLOC = ("held", "default")
MALLOC_NAMES = {"held": "freed memory kept (now)", "default": "glibc's default (before)"}


def _model(config: PolicyConfig, layout: torch.memory_format) -> tuple[PixelChunk, torch.optim.Optimizer]:
    torch.manual_seed(0)
    model = PixelChunk(config)
    model.memory_format = layout
    model.encoders.to(memory_format=layout)  # type: ignore[call-overload]
    return model, torch.optim.Adam(model.parameters(), lr=1e-3)


def _batch(config: PolicyConfig, size: int) -> Batch:
    g = torch.Generator().manual_seed(1)
    images = tuple(torch.randint(0, 256, (size, config.image_size, config.image_size, 3), dtype=torch.uint8,
                                 generator=g) for _ in config.cameras)
    return Batch(torch.randn(size, config.obs_size, generator=g),
                 torch.randn(size, config.chunk, ACTION_SIZE, generator=g), torch.ones(size, config.chunk),
                 images, torch.randn(size, len(config.blind), generator=g))


def _steps(config: PolicyConfig, model: PixelChunk, optimizer: torch.optim.Optimizer, batch: Batch, steps: int,
           bf16: bool) -> float:
    """Seconds a step, over `steps` steps."""
    start = time.perf_counter()
    for _ in range(steps):
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            loss = pixel_loss(config, model, batch)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    return (time.perf_counter() - start) / steps


def _child(args: argparse.Namespace) -> None:
    """One process's figures, as JSON on stdout: seconds a step per layout, and kernel CPU seconds a step."""
    if args.child == "held" and not hold_freed_memory():
        raise SystemExit("this process has no glibc mallopt to hold freed memory with")
    config, bf16 = _config(args)
    batch = _batch(config, args.batch_size)
    models = {name: _model(config, layout) for name, layout in LAYOUTS.items()}
    figures: dict[str, float] = {}
    for name, (model, optimizer) in models.items():
        _steps(config, model, optimizer, batch, 2, bf16)
        kernel = os.times().system
        figures[name] = _steps(config, model, optimizer, batch, args.steps, bf16)
        figures[name + " kernel"] = (os.times().system - kernel) / args.steps
    print(json.dumps(figures))


def _config(args: argparse.Namespace) -> tuple[PolicyConfig, bool]:
    if args.threads:
        torch.set_num_threads(args.threads)
    bf16 = args.precision == "bf16" or (args.precision == "auto" and native_bf16(torch.device("cpu")))
    cameras = tuple(c for c in args.cameras.split(",") if c)
    return PolicyConfig(kind="cnn-chunk", cameras=cameras, blind=tuple(range(10, 25)), obs_size=25,
                        image_size=args.image_size, image_quality="fast"), bf16


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--image-size", type=int, default=DEFAULT_IMAGE_SIZE)
    p.add_argument("--cameras", default="front,wrist")
    p.add_argument("--steps", type=int, default=10, help="timed steps per layout and process")
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--threads", type=int, default=0, help="torch threads (0: every core, as train does)")
    p.add_argument("--precision", choices=("auto", "fp32", "bf16"), default="auto")
    p.add_argument("--child", choices=MALLOC, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        _child(args)
        return
    config, bf16 = _config(args)
    argv = [sys.executable, "-m", "benchmarks.pixel_step", *sys.argv[1:]]
    times: dict[tuple[str, str], list[float]] = {}
    kernel: dict[tuple[str, str], list[float]] = {}
    for round_ in range(args.rounds):
        for malloc in MALLOC if round_ % 2 == 0 else MALLOC[::-1]:
            out = subprocess.run([*argv, "--child", malloc], capture_output=True, text=True, check=True).stdout
            figures = json.loads(out.splitlines()[-1])
            for name in LAYOUTS:
                times.setdefault((name, malloc), []).append(figures[name])
                kernel.setdefault((name, malloc), []).append(figures[name + " kernel"])
    base = (next(iter(LAYOUTS)), MALLOC[0])
    for name, value in machine("torch"):
        print(f"{name}: {value}")
    print(f"\none training step of cnn-chunk: batch {args.batch_size}, {len(config.cameras)} camera(s) at "
          f"{args.image_size} px, {'bf16' if bf16 else 'fp32'}, {torch.get_num_threads()} thread(s); medians over "
          f"{args.rounds} rounds of {args.steps} steps\n")
    print("| layout | malloc | ms a step | steps/s | kernel CPU ms a step | the first row is faster by |")
    print("|---|---|---|---|---|---|")
    for key, seconds in times.items():
        ratio = statistics.median(o / b for o, b in zip(seconds, times[base], strict=True))
        print(f"| {key[0]} | {MALLOC_NAMES[key[1]]} | {1000 * statistics.median(seconds):.0f} | "
              f"{1 / statistics.median(seconds):.1f} | {1000 * statistics.median(kernel[key]):.0f} | {ratio:.2f}x |")


if __name__ == "__main__":
    main()
