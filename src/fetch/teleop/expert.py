"""The task's scripted expert as a device: datasets with no person."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from fetch.teleop.devices import Command, DeviceKind


class ExpertDevice:
    """The task's scripted expert as a device: datasets with no person."""

    name = "expert"

    def __init__(self, env: Any) -> None:
        from fetch.experts import make_expert

        self.expert = make_expert(env)

    def reset(self) -> None:
        self.expert.reset()

    def poll(self, obs: Mapping[str, np.ndarray]) -> Command:
        return Command(np.asarray(self.expert(obs), dtype=np.float32))

    def close(self) -> None:
        pass


KIND = DeviceKind(
    name="expert", human=False, legend=(), add_arguments=None,
    summary="the task's scripted expert (no person, no display needed)",
    build=lambda context: ExpertDevice(context.env))
