"""gym-fetch-v2: the Fetch manipulation suite on modern MuJoCo; `import fetch` registers its ids."""

from __future__ import annotations

from typing import Any

from fetch._gl import guard_mujoco_import

guard_mujoco_import()  # before anything imports mujoco; it leaves the environment as it found it

import gymnasium as _gym  # noqa: E402

from fetch.errors import FetchError, UnknownNameError  # noqa: E402
from fetch.tasks import ENV_IDS, REGISTRATIONS  # noqa: E402

__version__ = "0.1.0"
__all__ = ["ENV_IDS", "FetchError", "UnknownNameError", "__version__", "make_vec"]


def make_vec(env_id: str, num_envs: int, **kwargs: Any) -> _gym.vector.VectorEnv:
    """N worlds of a registered id in one process, stepped on C threads (`fetch.vector.FetchVectorEnv`):
    `gym.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point", **kwargs)`."""
    return _gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)


for _reg in REGISTRATIONS:
    if _reg.env_id not in _gym.registry:
        # No passive env-checker or order-enforcing layer in every step's path: the test suite
        # runs gymnasium's full check_env on every id, and FetchEnv itself raises ResetNeeded on
        # a step before the first reset.
        _gym.register(id=_reg.env_id, entry_point="fetch.env:FetchEnv", kwargs={"task": _reg.task.name},
                      vector_entry_point="fetch.vector:FetchVectorEnv",
                      max_episode_steps=_reg.max_episode_steps, disable_env_checker=True,
                      order_enforce=False)
