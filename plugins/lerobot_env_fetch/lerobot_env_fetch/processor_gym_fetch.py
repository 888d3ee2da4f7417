"""A gym_fetch policy's LeRobot processors: batched and on the policy's device in, on the CPU out.

Nothing is normalised here: the run's checkpoint holds its own normalisation, which the policy applies.
"""

from __future__ import annotations

from typing import Any

from lerobot.processor import (
    AddBatchDimensionProcessorStep,
    DeviceProcessorStep,
    PolicyAction,
    PolicyProcessorPipeline,
    RenameObservationsProcessorStep,
    make_policy_processor_pipelines,
)

from lerobot_env_fetch.configuration_gym_fetch import GymFetchConfig


def make_gym_fetch_pre_post_processors(config: GymFetchConfig, dataset_stats: Any = None) -> tuple[
        PolicyProcessorPipeline[dict[str, Any], dict[str, Any]], PolicyProcessorPipeline[PolicyAction, PolicyAction]]:
    """LeRobot's default steps (lerobot-eval sets the renaming and the device on them) but the normalisation."""
    return make_policy_processor_pipelines(
        input_steps=[RenameObservationsProcessorStep(rename_map={}), AddBatchDimensionProcessorStep(),
                     DeviceProcessorStep(device=str(config.device))],
        output_steps=[DeviceProcessorStep(device="cpu")])
