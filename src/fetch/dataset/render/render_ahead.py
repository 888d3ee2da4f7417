"""Images of many demos' states, in order, rendered by worker processes a few demos ahead of the caller."""

from __future__ import annotations

import collections
import concurrent.futures
import dataclasses
import sys
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from fetch.errors import DatasetError

RESTARTS = 2
"""How often the workers are started again after one died (a native crash, the kernel's
out-of-memory killer), rendering the demos in flight again. A death that comes back every time
still ends the work with a clear error."""

@dataclasses.dataclass
class _Job:
    name: str
    states: np.ndarray | None
    seed: int | None
    """the episode's reset seed (its looks, where the env draws them)."""
    future: concurrent.futures.Future[dict[str, np.ndarray]] | None = None
    """None until submitted to the current workers (and for no states)."""


def render_ahead(env_id: str, env_kwargs: dict[str, Any], size: int, workers: int,
                 jobs: Iterable[tuple[str, np.ndarray | None, int | None]],
                 cameras: Sequence[str], quality: str = "full") -> Iterator[dict[str, np.ndarray] | None]:
    """For each (demo name, its states (N, state size), its reset seed), the images per camera ((N, size, size, 3)
    uint8, drawn at `quality`), in order; None for None. At most 2 x `workers` demos are in flight, not every demo's
    images at once. A worker that dies is replaced `RESTARTS` times at most (said on stderr)."""
    from fetch.dataset.render.frames import RenderPool

    workers = max(1, workers)
    source = iter(jobs)
    pending: collections.deque[_Job] = collections.deque()
    restarts = RESTARTS
    pool = RenderPool(env_id, env_kwargs, size, workers, quality=quality)
    try:
        while True:
            try:
                while len(pending) < 2 * workers and (job := next(source, None)) is not None:
                    pending.append(_Job(*job))
                for waiting in pending:
                    if waiting.states is not None and waiting.future is None:
                        waiting.future = pool.submit(waiting.states, tuple(cameras), waiting.seed)
                if not pending:
                    return
                first = pending[0]
                images = None if first.future is None else first.future.result()
            except concurrent.futures.process.BrokenProcessPool as e:
                if not restarts:
                    raise DatasetError(f"a render worker died while rendering {pending[0].name}, after "
                                       f"{RESTARTS} restarts: {e}") from e
                restarts -= 1
                print(f"a render worker died while rendering {pending[0].name}; starting new workers to render "
                      f"it again ({restarts} more restart(s) allowed)", file=sys.stderr, flush=True)
                for waiting in pending:
                    waiting.future = None
                pool.replace_workers()
                continue
            pending.popleft()
            yield images
    finally:
        pool.close()  # its own thread cancels the demos not yet started (see stop_pool)
