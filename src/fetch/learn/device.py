"""A trained policy as a collection device (`gym-fetch collect --device policy --policy RUN/`): a person
watches it, or records what it does. Declared here and registered with the collector's devices
(`fetch.teleop.registry.register`) when this module is imported, which `gym-fetch` does; the
policy and torch are loaded only when the device is built."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from fetch.errors import FetchError
from fetch.robot import ACTION_STEP
from fetch.teleop.devices import Command, Device, DeviceContext, DeviceKind
from fetch.teleop.registry import register


class PolicyDevice:
    """Drives the arm with the policy of a `gym-fetch train` run, so a person can watch it act (and
    the demos it succeeds in are recorded like any other device's)."""

    name = "policy"

    def __init__(self, env: Any, run_dir: str | os.PathLike[str]) -> None:
        import torch

        from fetch.learn import load

        # One observation at a time runs fastest on one thread: a pixel policy's step took 2 ms on one
        # and 16 ms on two cores that the renderer and the window also use (docs/training.md).
        torch.set_num_threads(1)
        self.policy = load(run_dir)
        env_id = env.spec.id if getattr(env, "spec", None) is not None else None
        if env_id is not None and env_id != self.policy.env_id:
            raise FetchError(f"the policy in {run_dir} was trained on {self.policy.env_id}, not {env_id}; "
                             f"collect with --env {self.policy.env_id}")
        self._env = env.unwrapped
        self._cameras: Any = None
        if self.policy.config.cameras:
            # A pixel policy's images are rendered here, from the state the observation describes, as the env
            # renders them with cameras=, in the look it learnt from (its hide_goal and image quality); the dataset
            # keeps its own.
            from fetch.camera_obs import CameraImages, check_cameras

            cameras = check_cameras(self._env.model, self.policy.config.cameras, self.policy.config.image_size)
            self._cameras = CameraImages(self._env.model, cameras, self.policy.config.image_size,
                                         bool(self.policy.env_kwargs.get("hide_goal", False)),
                                         self.policy.config.image_quality)

    def reset(self) -> None:
        self.policy.reset()

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        if self._cameras is not None:
            obs = {**obs, **self._cameras.render(self._env.data)}
        action = self.policy(obs)
        return Command(action, status=unsure_status(self.policy.spread))

    def close(self) -> None:
        if self._cameras is not None:
            self._cameras.close()


def unsure_status(spread: float | np.ndarray | None) -> str:
    """The window's note of how unsure the policy is: the spread of the predictions its action was made from
    (`Policy.spread`; a batch's widest) as millimetres of hand target; "" where it makes one prediction."""
    if spread is None:
        return ""
    return f"unsure {float(np.max(spread)) * ACTION_STEP * 1000:.0f} mm"


@dataclasses.dataclass(frozen=True)
class PolicyOptions:
    """The policy device's flag (the takeover device reads it too)."""

    policy: str | None = None
    """the run directory `gym-fetch train` wrote."""


def add_policy_arguments(p: Any) -> None:
    p.add_argument("--policy", default=None, metavar="RUN",
                   help="with --device policy: the run directory `gym-fetch train` wrote")


def build_policy(context: DeviceContext) -> Device:
    run = context.options_for(PolicyOptions).policy
    if not run:
        raise FetchError("--device policy needs --policy RUN (a directory written by `gym-fetch train`)")
    return PolicyDevice(context.env, run)


KIND = register(DeviceKind(
    name="policy", human=False, legend=(), add_arguments=add_policy_arguments, options=PolicyOptions,
    build=build_policy,
    summary="a policy trained by `gym-fetch train` (--policy RUN)"))
