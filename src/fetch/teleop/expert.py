"""The task's scripted expert as a device: datasets with no person.

By default the expert records under DART noise (Laskey et al. 2017): the arm executes the expert's
action plus Gaussian noise, so the demos visit the states a learned policy drifts into, and each step
also records the expert's clean action there (`expert_actions`), which is what `gym-fetch train`
learns. `actions` stays what the arm did, so the demo replays exactly. docs/training.md ("Why these
defaults") has the measurements behind the default; `--expert-noise 0` records the plain expert. a[3] is metres of
finger target, so the same 0.1 there swings the fingers between open and closed from step to step;
`--expert-finger-noise 0.005` perturbs them as many metres as the hand (docs/training.md, "Why
these defaults").
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from fetch.errors import FetchError
from fetch.robot import dart_std
from fetch.teleop.devices import Command, DeviceContext, DeviceKind

EXPERT_NOISE = 0.1
"""Default std of the Gaussian noise on the executed action (the expert table's noise level)."""


class ExpertDevice:
    """The task's expert; with `noise` > 0 it executes a perturbed action and labels the clean one."""

    name = "expert"

    def __init__(self, env: Any, noise: float = 0.0, seed: int = 0, finger_noise: float | None = None) -> None:
        from fetch.experts import make_expert

        if not (math.isfinite(noise) and noise >= 0):
            raise FetchError(f"--expert-noise must be a finite std >= 0 (0: the plain expert), got {noise!r}")
        if finger_noise is not None and not (math.isfinite(finger_noise) and finger_noise >= 0):
            raise FetchError(f"--expert-finger-noise must be a finite std >= 0, got {finger_noise!r}")
        self.expert = make_expert(env)
        self.noise = float(noise)
        self.std = dart_std(self.noise, finger_noise)
        """(4,) the noise's std on each action entry (`dart_std`)."""
        self.rng = np.random.default_rng(seed)

    def reset(self) -> None:
        self.expert.reset()

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        clean = np.asarray(self.expert(obs), dtype=np.float32)
        if not self.std.any():
            return Command(clean)
        noisy = np.clip(clean + self.rng.normal(0.0, 1.0, clean.shape) * self.std, -1.0, 1.0)
        return Command(noisy.astype(np.float32), label=clean)

    def close(self) -> None:
        pass


@dataclasses.dataclass(frozen=True)
class ExpertOptions:
    """The expert device's flags."""

    expert_noise: float = EXPERT_NOISE
    """std of the Gaussian noise on the executed action (0: the plain expert)."""
    expert_finger_noise: float | None = None
    """std of that noise on a[3], metres of finger target (None: `expert_noise`)."""


def add_expert_arguments(p: Any) -> None:
    p.add_argument("--expert-noise", type=float, default=EXPERT_NOISE, metavar="STD",
                   help="with --device expert: std of the Gaussian noise added to the executed action, the "
                        "expert's clean action being recorded as `expert_actions` for training (DART; "
                        "default %(default)s; 0: the plain expert)")
    p.add_argument("--expert-finger-noise", type=float, default=None, metavar="STD",
                   help="with --device expert: std of that noise on a[3], metres of finger target (a finger travels "
                        "0.05); default --expert-noise (0.1: the fingers swing open and shut; 0.005 is the hand's "
                        "metres)")


def build_expert(context: DeviceContext) -> ExpertDevice:
    options = context.options_for(ExpertOptions)
    return ExpertDevice(context.env, options.expert_noise, context.seed, options.expert_finger_noise)


KIND = DeviceKind(
    name="expert", human=False, legend=(), add_arguments=add_expert_arguments, options=ExpertOptions,
    holds_past_success=True,
    summary="the task's scripted expert (no person, no display needed), under DART noise by default",
    build=build_expert)
