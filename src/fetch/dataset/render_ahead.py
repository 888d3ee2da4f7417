"""Images of many demos' states, in order, rendered by worker processes a few demos ahead of the caller."""

from __future__ import annotations

import collections
import concurrent.futures
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from fetch.errors import DatasetError

_END = object()


def render_ahead(env_id: str, env_kwargs: dict[str, Any], size: int, workers: int,
                 states: Iterable[np.ndarray | None], cameras: Sequence[str]) -> Iterator[dict[str, np.ndarray] | None]:
    """For each array of states (N, state size), its images per camera ((N, size, size, 3) uint8), in
    order; None for None. At most 2 x `workers` demos are in flight, not every demo's images at once."""
    from fetch.dataset.frames import RenderPool

    with RenderPool(env_id, env_kwargs, size, max(1, workers)) as pool:
        source = iter(states)
        pending: collections.deque[concurrent.futures.Future[dict[str, np.ndarray]] | None] = collections.deque()

        def submit_next() -> None:
            array = next(source, _END)
            if isinstance(array, np.ndarray):
                pending.append(pool.submit(array, tuple(cameras)))
            elif array is None:
                pending.append(None)

        for _ in range(2 * max(1, workers)):
            submit_next()
        try:
            while pending:
                future = pending.popleft()
                submit_next()
                if future is None:
                    yield None
                    continue
                try:
                    yield future.result()
                except concurrent.futures.process.BrokenProcessPool as e:
                    raise DatasetError(f"a render worker died: {e}") from e
        finally:
            for future in pending:
                if future is not None:
                    future.cancel()
