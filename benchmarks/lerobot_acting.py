"""How fast a LeRobot policy acts, timed inside lerobot-eval itself.

    python -m benchmarks.lerobot_acting --policy.path=POLICY --env.type=fetch ...   # lerobot-eval's arguments

Runs `lerobot-eval` with the policy's `select_action` timed (the network, its action queue and, for Diffusion
Policy, every denoising step; not the env, the processors or the videos), and prints as its last line
`{"actions": N, "seconds": S}`: actions handed out and the time spent making them. Run it with the Python of a
LeRobot 0.6 venv (`benchmarks.side_by_side` does).
"""

from __future__ import annotations

import json
import time
from typing import Any

from lerobot.scripts import lerobot_eval

TIMES: list[tuple[float, int]] = []
"""([s] a `select_action` call's time, the actions it returned), in order."""


def timed(make_policy: Any) -> Any:
    """`make_policy`, its policy's `select_action` timed into `TIMES`."""

    def make(*args: Any, **kwargs: Any) -> Any:
        policy = make_policy(*args, **kwargs)
        select_action = policy.select_action

        def select_timed(batch: Any, *more: Any, **named: Any) -> Any:
            start = time.perf_counter()
            action = select_action(batch, *more, **named)
            TIMES.append((time.perf_counter() - start, int(action.shape[0])))
            return action

        policy.select_action = select_timed
        return policy

    return make


def main() -> None:
    lerobot_eval.make_policy = timed(lerobot_eval.make_policy)
    lerobot_eval.main()  # reads sys.argv as lerobot-eval does
    print(json.dumps({"actions": sum(n for _, n in TIMES), "seconds": sum(s for s, _ in TIMES)}))


if __name__ == "__main__":
    main()
