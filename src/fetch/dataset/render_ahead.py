"""Images of many demos' states, in order, rendered by worker processes a few demos ahead of the caller."""

from __future__ import annotations

import collections
import concurrent.futures
import sys
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from fetch.errors import DatasetError

RESTARTS = 2
"""How often the workers are started again after one died (a native crash, the kernel's
out-of-memory killer), rendering the demos in flight again. A death that comes back every time
still ends the work with a clear error."""

_UNSENT = object()


def render_ahead(env_id: str, env_kwargs: dict[str, Any], size: int, workers: int,
                 jobs: Iterable[tuple[str, np.ndarray | None]],
                 cameras: Sequence[str]) -> Iterator[dict[str, np.ndarray] | None]:
    """For each (demo name, its states (N, state size)), the images per camera ((N, size, size, 3)
    uint8), in order; None for None. At most 2 x `workers` demos are in flight, not every demo's
    images at once. A worker that dies is replaced `RESTARTS` times at most (said on stderr)."""
    from fetch.dataset.frames import RenderPool

    workers = max(1, workers)
    source = iter(jobs)
    # [name, states, future]: the future is None for no states, _UNSENT until submitted.
    pending: collections.deque[list[Any]] = collections.deque()
    restarts = RESTARTS
    pool = RenderPool(env_id, env_kwargs, size, workers)
    try:
        while True:
            try:
                for entry in pending:
                    if entry[2] is _UNSENT:
                        entry[2] = pool.submit(entry[1], tuple(cameras))
                while len(pending) < 2 * workers and (job := next(source, None)) is not None:
                    name, states = job
                    pending.append([name, states, None if states is None else _UNSENT])
                    if states is not None:
                        pending[-1][2] = pool.submit(states, tuple(cameras))
                if not pending:
                    return
                future = pending[0][2]
                images = None if future is None else future.result()
            except concurrent.futures.process.BrokenProcessPool as e:
                name = pending[0][0]
                if not restarts:
                    raise DatasetError(f"a render worker died while rendering {name}, after {RESTARTS} "
                                       f"restarts: {e}") from e
                restarts -= 1
                print(f"a render worker died while rendering {name}; starting new workers to render it again "
                      f"({restarts} more restart(s) allowed)", file=sys.stderr, flush=True)
                for entry in pending:
                    if entry[2] is not None:
                        entry[2] = _UNSENT
                pool.close()
                pool = RenderPool(env_id, env_kwargs, size, workers)
                continue
            pending.popleft()
            yield images
    finally:
        for entry in pending:
            if isinstance(entry[2], concurrent.futures.Future):
                entry[2].cancel()
        pool.close()
