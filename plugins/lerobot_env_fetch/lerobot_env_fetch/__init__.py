"""gym-fetch-v2's tasks as a LeRobot environment: `--env.type=fetch --env.task=Bin-pick-v2`.

LeRobot imports this distribution (its name starts with `lerobot_env_`) in lerobot-train, lerobot-eval and
lerobot-record; importing it registers `FetchEnvConfig` as the env type `fetch`, the gym ids
`lerobot_env_fetch/<env id>` (`env.py`) and the policy type `gym_fetch`: a `gym-fetch train` run in
LeRobot's pretrained-policy layout, written by `export_policy` (`configuration_gym_fetch`,
`modeling_gym_fetch`). Observation keys and shapes are the features `gym-fetch export --to lerobot`
declares for the same cameras and image size (docs/lerobot_env.md has the table).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

import fetch
from fetch.dataset.exports.lerobot import IMAGE_QUALITY
from fetch.errors import UnknownNameError
from fetch.rendering import check_image_quality
from fetch.timing import CONTROL_DT
from lerobot_env_fetch.configuration_gym_fetch import GymFetchConfig
from lerobot_env_fetch.env import NAMESPACE, LeRobotFetch, gym_id, make, register

__all__ = ["FetchEnvConfig", "GymFetchConfig", "LeRobotFetch", "make", "parse_cameras"]

register()


def parse_cameras(cameras: str) -> tuple[str, ...]:
    """`--env.cameras` as `gym-fetch export --cameras` reads it: comma-separated names, `none` (or empty) for none."""
    names = tuple(c.strip() for c in cameras.split(",") if c.strip())
    return () if names == ("none",) else names


@EnvConfig.register_subclass("fetch")
@dataclass
class FetchEnvConfig(EnvConfig):
    """One of gym-fetch-v2's ids (`task`). `cameras` and `image_size` [px] as the export's `--cameras` and
    `--image-size` (their defaults too), drawn at `image_quality` (the export's; a `gym-fetch train` run that
    learnt from images drawn otherwise is evaluated at its own): with cameras, `observation.state` is the
    robot's own readings and each camera's image is `observation.images.<camera>`; `cameras=none` is a state
    policy's env (the whole observation vector). `episode_length` [steps] overrides the id's 50; `video_size`
    [px] is the side of lerobot-eval's videos; `terminate_on_success` ends an episode at its first success."""

    task: str | None = "Bin-pick-v2"
    fps: int = round(1.0 / CONTROL_DT)
    cameras: str = "front,wrist"
    image_size: int = 128
    hide_goal: bool = False
    image_quality: str = IMAGE_QUALITY
    episode_length: int | None = None
    terminate_on_success: bool = True
    video_size: int = 256
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        task = self.task
        if task is None or task not in fetch.ENV_IDS:
            raise UnknownNameError("env.task", task, fetch.ENV_IDS)
        # The features are read from the env itself (which checks the cameras and the size).
        probe = make(task, parse_cameras(self.cameras), self.image_size, self.hide_goal,
                     image_quality=check_image_quality(self.image_quality, "env.image_quality"))
        shapes, action = probe.shapes, probe.action_space.shape
        probe.close()
        kinds = {"agent_pos": (FeatureType.STATE, OBS_STATE), "environment_state": (FeatureType.ENV, OBS_ENV_STATE)}
        self.features = {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=tuple(action or ()))}
        self.features_map = {ACTION: ACTION}
        for key, shape in shapes.items():
            kind, policy_key = kinds.get(key, (FeatureType.VISUAL, f"{OBS_IMAGES}.{key.removeprefix('pixels/')}"))
            self.features[key] = PolicyFeature(type=kind, shape=shape)
            self.features_map[key] = policy_key

    @property
    def package_name(self) -> str:
        return NAMESPACE

    @property
    def gym_id(self) -> str:
        return gym_id(str(self.task))

    @property
    def gym_kwargs(self) -> dict:
        kwargs = {"cameras": parse_cameras(self.cameras), "image_size": self.image_size, "hide_goal": self.hide_goal,
                  "image_quality": self.image_quality,
                  "terminate_on_success": self.terminate_on_success, "render_mode": "rgb_array",
                  "width": self.video_size, "height": self.video_size}
        if self.episode_length is not None:
            kwargs["max_episode_steps"] = self.episode_length
        return kwargs
