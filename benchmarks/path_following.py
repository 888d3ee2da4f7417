"""How closely `gym-fetch generate`'s hand follows the carried-over path, at each `--hand-response`.

    python -m benchmarks.path_following [--tasks Drawer-close-v2,PickPlace-v2] [--source DIR] [--demos 200]
        [--responses 1,0.64] [--out /tmp/path-following]

generate commands each step the hand's distance to its path divided by `--hand-response`; the hand covers about
`fetch.robot.HAND_RESPONSE` (0.64) of a commanded step. For each task, from `--source` (pad demos of that task)
or else 10 of the scripted expert's demos, it generates `--demos` demos at each response (one worker, seed 100:
the same attempts at each) and reads from the datasets:

- attempts kept: the share of attempts (up to the last kept) that succeeded;
- on the drawer tasks, where the fingers must come down into the 4 cm slot behind the handle (Drawer-close can
  also push the handle from the robot's side): the demos whose fingertips go below the drawer front's top by
  step 20, later, or never (they came down on the front and dragged the drawer by friction).

Prints one table; the datasets stay under `--out` (a dataset already there is read, not made again).
"""

from __future__ import annotations

import argparse
import pathlib
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks._machine import machine_line
from fetch.cli import main as gym_fetch
from fetch.dataset import open_dataset

TASKS = ("Drawer-close-v2", "Drawer-open-v2", "PickPlace-v2", "Bin-pick-v2", "Bin-place-v2", "Box-open-v2",
         "Box-close-v2")
SLOT_Z = 0.51
"""[m] the grip site's height with the fingertips below the top of the drawer's front (it is 0.528 resting on
the front's top edge, 0.456 hooked)."""
EARLY = 20
"""[steps] a hook by this step is the source's timing (its pad demos hooked at steps 12-20)."""


def grip_slice(env_id: str) -> slice:
    """Where the grip site's position lies in `env_id`'s observation."""
    env = gym.make(env_id)
    try:
        return env.unwrapped.observation_layout["grip_pos"]
    finally:
        env.close()


def stats(dataset: pathlib.Path, grip: slice) -> dict[str, Any]:
    """The demos' figures (module docstring) from a generated dataset; `grip`: `grip_slice` of its task."""
    hooks = {"early": 0, "later": 0, "never": 0}
    with open_dataset(dataset) as ds:
        response = float(ds.settings["generate"].get("hand_response", 1.0))
        attempts = 1 + max(int(ds.attrs(n)["attempt"]) for n in ds.demo_names)  # up to the last kept
        for name in ds.demo_names:
            height = ds.arrays(name, keep=lambda key: key == "obs/observation")["obs/observation"][:, grip][:, 2]
            low = np.nonzero(height < SLOT_Z)[0]
            hooks["never" if not len(low) else "early" if low[0] < EARLY else "later"] += 1
        demos = len(ds.demo_names)
    return {"response": response, "demos": demos, "attempts": attempts, "hooks": hooks}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", default=",".join(TASKS))
    parser.add_argument("--source", default=None, help="pad demos to generate from (one task); default: the expert's")
    parser.add_argument("--demos", type=int, default=200)
    parser.add_argument("--responses", default="1,0.64", help="--hand-response values, comma-separated")
    parser.add_argument("--out", default="/tmp/path-following")
    args = parser.parse_args()
    tasks = args.tasks.split(",")
    if args.source and len(tasks) != 1:
        parser.error("--source is one task's demos: give that task alone in --tasks")
    out = pathlib.Path(args.out)
    print(machine_line())
    rows = []
    for env_id in tasks:
        grip = grip_slice(env_id)
        source = pathlib.Path(args.source) if args.source else out / env_id / "expert"
        if not source.exists():
            assert gym_fetch(["collect", "--env", env_id, "--device", "expert", "--episodes", "10", "--render", "none",
                              "--out", str(source)]) == 0
        for response in args.responses.split(","):
            target = out / env_id / f"{source.parent.name}-{source.name}-r{response}"
            if (target / "demos.hdf5").exists():
                with open_dataset(target) as ds:
                    made_from = ds.settings["generate"]["source"]
                if pathlib.Path(made_from).resolve() not in (source.resolve(), (source / "demos.hdf5").resolve()):
                    raise SystemExit(f"{target} was generated from {made_from}, not {source}: use another --out")
            else:
                assert gym_fetch(["generate", "--source", str(source), "--out", str(target), "--demos",
                                  str(args.demos), "--workers", "1", "--seed", "100", "--hand-response", response]) == 0
            rows.append((env_id, f"{source.parent.name}/{source.name}", stats(target, grip)))
    print("\n| task | from | hand response | demos (attempts) | kept | drawer: fingers below its front by step 20 / "
          "later / never |")
    print("|---|---|---|---|---|---|")
    for env_id, source_name, s in rows:
        hooks = s["hooks"]
        slot = (f"{hooks['early']} / {hooks['later']} / {hooks['never']}" if env_id.startswith("Drawer") else "")
        print(f"| {env_id} | {source_name} | {s['response']:g} | {s['demos']} ({s['attempts']}) | "
              f"{100 * s['demos'] / s['attempts']:.0f} % | {slot} |")


if __name__ == "__main__":
    main()
