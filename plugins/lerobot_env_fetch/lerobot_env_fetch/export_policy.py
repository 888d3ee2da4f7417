"""Write a `gym-fetch train` run as a LeRobot pretrained policy: `python -m lerobot_env_fetch.export_policy RUN OUT`.

OUT then holds `config.json` (type `gym_fetch`), the run's `checkpoint.pt` as it is, and the processors'
files, which `lerobot-eval --policy.path=OUT --env.type=fetch ...` loads like any LeRobot policy (and
`huggingface-cli upload` can publish). The command it prints evaluates it as `gym-fetch eval` does.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import shutil
import sys

from lerobot.configs import FeatureType, PolicyFeature
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

import fetch.learn
from fetch.dataset.exports.lerobot import env_flags
from fetch.errors import FetchError
from fetch.learn import checkpoint
from fetch.learn.evaluate import EVAL_SEED_START
from fetch.learn.runtime import Policy
from fetch.tasks import registered_horizon
from lerobot_env_fetch.configuration_gym_fetch import GymFetchConfig
from lerobot_env_fetch.modeling_gym_fetch import Inputs
from lerobot_env_fetch.processor_gym_fetch import make_gym_fetch_pre_post_processors

SAME_ENV = {"reward_type": None, "hide_goal": None, "looks": "plain"}
"""The env settings of a run's dataset the env LeRobot makes can match (None: any value; a value: only it).
The reward type changes LeRobot's `avg_sum_reward`, never success."""


def config_of(policy: Policy) -> GymFetchConfig:
    """The LeRobot config describing `policy`: its task, inputs and the env it needs (refused where the
    env LeRobot makes cannot give what it saw)."""
    differs = {k: v for k, v in policy.env_kwargs.items() if k not in SAME_ENV or SAME_ENV[k] not in (None, v)}
    if differs:
        raise FetchError(f"the run learnt from demos recorded with {differs}, which the LeRobot env does not offer")
    inputs = Inputs.of(policy)
    features = {OBS_STATE: PolicyFeature(type=FeatureType.STATE, shape=(len(inputs.state),)),
                OBS_ENV_STATE: PolicyFeature(type=FeatureType.ENV, shape=(3,))}
    size = policy.config.image_size
    for camera in policy.config.cameras:
        features[f"{OBS_IMAGES}.{camera}"] = PolicyFeature(type=FeatureType.VISUAL, shape=(3, size, size))
    return GymFetchConfig(env_id=policy.env_id, cameras=list(policy.config.cameras), image_size=size,
                          image_quality=policy.config.image_quality,
                          hide_goal=bool(policy.env_kwargs.get("hide_goal", False)), horizon=policy.horizon,
                          device="cpu", input_features=features,
                          output_features={ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(4,))})


def export_policy(run: str | os.PathLike[str], out: str | os.PathLike[str]) -> GymFetchConfig:
    """Write `run`'s policy (a `gym-fetch train` run directory) into the new or empty folder `out`."""
    target = pathlib.Path(out)
    if target.exists() and (not target.is_dir() or any(target.iterdir())):
        raise FetchError(f"{target} exists and is not an empty folder; choose a new one")
    config = config_of(fetch.learn.load(run))
    target.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(checkpoint.file_of(run), checkpoint.path(target))
    config.save_pretrained(target)
    for pipeline in make_gym_fetch_pre_post_processors(config):
        pipeline.save_pretrained(target)
    if config_of(fetch.learn.load(target)) != config:  # the copy is the run that was checked
        raise FetchError(f"{run} changed while it was copied (is it still training?); export it again")
    return config


def eval_command(out: str | os.PathLike[str], config: GymFetchConfig, episodes: int = 100) -> list[str]:
    """The lerobot-eval command that evaluates the exported policy as `gym-fetch eval` does: its env, its
    episode length, `gym-fetch eval`'s first seed."""
    command = ["lerobot-eval", f"--policy.path={out}",
               *env_flags(config.env_id, config.cameras, config.image_size, config.image_quality, config.hide_goal)]
    if config.horizon != registered_horizon(config.env_id):
        command.append(f"--env.episode_length={config.horizon}")
    return command + [f"--eval.n_episodes={episodes}", f"--seed={EVAL_SEED_START}", "--policy.device=cpu"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m lerobot_env_fetch.export_policy", description=__doc__)
    parser.add_argument("run", help="a `gym-fetch train` run directory")
    parser.add_argument("out", help="a new folder for the LeRobot policy")
    args = parser.parse_args(argv)
    try:
        config = export_policy(args.run, args.out)
    except FetchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {args.run}'s {config.env_id} policy as a LeRobot policy in {args.out}; evaluate it with:\n"
          f"  {' '.join(eval_command(args.out, config))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
