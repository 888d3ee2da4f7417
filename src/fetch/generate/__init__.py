"""Many demonstrations from a few: subtask segmentation, object-centric generation, workers and Ray."""

from __future__ import annotations

from fetch.generate.attempt import Options
from fetch.generate.run import GenerateConfig, Summary, generate

__all__ = ["GenerateConfig", "Options", "Summary", "generate"]
