"""Worker processes that end with the process that started them."""

from __future__ import annotations

import os
import threading
import time


def exit_with_parent(parent: int, period: float = 0.5) -> None:
    """End this worker once its parent is gone: a SIGKILLed parent runs no shutdown, and its workers
    would stay, stuck writing to a dead pipe or waiting for work (~136-276 MB each, forever). A watch
    on the parent's pid, not PR_SET_PDEATHSIG: that fires when the *thread* that started the worker
    ends, and a writer's thread starts some of them."""
    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(period)
        os._exit(1)

    threading.Thread(target=watch, name="fetch-exit-with-parent", daemon=True).start()
