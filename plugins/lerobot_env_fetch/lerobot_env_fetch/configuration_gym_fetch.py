"""`--policy.type=gym_fetch`: a `gym-fetch train` run as a LeRobot policy (its settings; `modeling_gym_fetch` acts).

LeRobot finds the policy class by convention from this module's name (`configuration_*` -> `modeling_*`,
`GymFetchConfig` -> `GymFetchPolicy`) and the processors likewise (`processor_*`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs import PreTrainedConfig
from lerobot.optim import LRSchedulerConfig, OptimizerConfig

from fetch.errors import FetchError

TYPE = "gym_fetch"


@PreTrainedConfig.register_subclass(TYPE)
@dataclass
class GymFetchConfig(PreTrainedConfig):
    """What the env of a `gym-fetch train` run's policy must give: its task, the cameras and their size [px]
    and drawing quality (none: a state policy), whether the goal marker was hidden, and the episode length
    [steps] it is given (`gym-fetch eval`'s). The policy itself (weights, normalisation, settings) is the
    run's `checkpoint.pt` beside this file, checked as `gym-fetch eval` checks it; these fields describe it
    and are checked against it."""

    env_id: str = ""
    cameras: list[str] = field(default_factory=list)
    image_size: int = 0
    image_quality: str = ""
    hide_goal: bool = False
    horizon: int = 50
    push_to_hub: bool = False

    @property
    def observation_delta_indices(self) -> None:
        return None

    @property
    def action_delta_indices(self) -> None:
        return None

    @property
    def reward_delta_indices(self) -> None:
        return None

    def get_optimizer_preset(self) -> OptimizerConfig:
        raise FetchError("a gym_fetch policy is trained with `gym-fetch train`, not lerobot-train")

    def get_scheduler_preset(self) -> LRSchedulerConfig | None:
        return None

    def validate_features(self) -> None:
        action = self.action_feature
        if action is not None and tuple(action.shape) != (4,):
            raise FetchError(f"a gym_fetch policy acts with 4 values (dx, dy, dz, gripper), not {tuple(action.shape)}")
