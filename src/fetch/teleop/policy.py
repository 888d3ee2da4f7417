"""A trained policy as a device (`--device policy --policy RUN/`): a person watches it, or records
what it does. The policy and torch are loaded by `fetch.learn` only when the device is built."""

from __future__ import annotations

from typing import Any

from fetch.errors import FetchError
from fetch.teleop.devices import Device, DeviceContext, DeviceKind


def add_policy_arguments(p: Any) -> None:
    p.add_argument("--policy", default=None, metavar="RUN",
                   help="with --device policy: the run directory `gym-fetch train` wrote")


def build_policy(context: DeviceContext) -> Device:
    run = getattr(context.args, "policy", None)
    if not run:
        raise FetchError("--device policy needs --policy RUN (a directory written by `gym-fetch train`)")
    from fetch.learn.device import PolicyDevice

    return PolicyDevice(context.env, run)  # type: ignore[no-any-return]


KIND = DeviceKind(
    name="policy", human=False, legend=(), add_arguments=add_policy_arguments, build=build_policy,
    summary="a policy trained by `gym-fetch train` (--policy RUN)")
