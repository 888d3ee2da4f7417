"""Many worlds per process: a Gymnasium VectorEnv that steps N Fetch worlds on C threads."""

from __future__ import annotations

from fetch.vector.env import FetchVectorEnv
from fetch.vector.worlds import has_batch

__all__ = ["FetchVectorEnv", "has_batch"]
