"""A trained policy as a collection device (`gym-fetch collect --device policy --policy RUN/`): a person
watches it, or records what it does. Declared here and registered with the collector's devices
(`fetch.teleop.registry.register`) when this module is imported, which `gym-fetch` does; the
policy and torch are loaded only when the device is built."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from fetch.errors import FetchError
from fetch.teleop.devices import Command, Device, DeviceContext, DeviceKind
from fetch.teleop.registry import register


class PolicyDevice:
    """Drives the arm with the policy of a `gym-fetch train` run, so a person can watch it act (and
    the demos it succeeds in are recorded like any other device's)."""

    name = "policy"

    def __init__(self, env: Any, run_dir: str | os.PathLike[str]) -> None:
        from fetch.learn import load

        self.policy = load(run_dir)
        env_id = env.spec.id if getattr(env, "spec", None) is not None else None
        if env_id is not None and env_id != self.policy.env_id:
            raise FetchError(f"the policy in {run_dir} was trained on {self.policy.env_id}, not {env_id}; "
                             f"collect with --env {self.policy.env_id}")

    def reset(self) -> None:
        self.policy.reset()

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        return Command(self.policy(obs))

    def close(self) -> None:
        pass


def add_policy_arguments(p: Any) -> None:
    p.add_argument("--policy", default=None, metavar="RUN",
                   help="with --device policy: the run directory `gym-fetch train` wrote")


def build_policy(context: DeviceContext) -> Device:
    run = getattr(context.args, "policy", None)
    if not run:
        raise FetchError("--device policy needs --policy RUN (a directory written by `gym-fetch train`)")
    return PolicyDevice(context.env, run)


KIND = register(DeviceKind(
    name="policy", human=False, legend=(), add_arguments=add_policy_arguments, build=build_policy,
    summary="a policy trained by `gym-fetch train` (--policy RUN)"))
