"""Demonstration datasets: robomimic's HDF5 layout, written crash-safely, read and replayed exactly."""

from __future__ import annotations

from fetch.dataset.episode import Demo, EpisodeBuffer
from fetch.dataset.reader import Dataset, open_dataset, summarize
from fetch.dataset.schema import Layout
from fetch.dataset.validation import validate
from fetch.dataset.writer import DatasetWriter, Header

__all__ = ["Dataset", "DatasetWriter", "Demo", "EpisodeBuffer", "Header", "Layout", "open_dataset", "summarize",
           "validate"]
