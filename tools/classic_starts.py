"""Write src/fetch/assets/classic_starts.npz: the start state of each of gymnasium-robotics' Fetch*-v4 scenes.

Each v4 env computes its start when it is made (the arm pulled to its start for 10 control steps); on
mujoco 3.11, the newest the v4 envs run on, that is the start the classic tasks' seeds were drawn
around, and `fetch.env` loads it so the start is the same on any mujoco. Run it, from the repository
root, in the mujoco 3.11 virtualenv that the parity benchmark makes:

    python -m benchmarks.parity_v4 --venv /tmp/v4venv
    /tmp/v4venv/bin/python -m tools.classic_starts            # writes the package's file
    /tmp/v4venv/bin/python -m tools.classic_starts --out /tmp/starts.npz
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

from benchmarks.parity_v4 import PAIRS
from fetch.compiled import CLASSIC_STARTS


def record_starts(path: pathlib.Path) -> None:
    """The start state (qpos, qvel, time, grip site, object height) of each v4 env's scene, keyed by
    the scene file's name, and the mujoco and gymnasium-robotics versions that computed them."""
    import gymnasium as gym
    import gymnasium_robotics
    import mujoco

    gym.register_envs(gymnasium_robotics)
    arrays: dict[str, np.ndarray] = {}
    for theirs_id in PAIRS.values():
        u = gym.make(theirs_id).unwrapped
        scene = pathlib.Path(u.fullpath).name
        arrays[f"{scene}/qpos"], arrays[f"{scene}/qvel"] = u.initial_qpos, u.initial_qvel
        arrays[f"{scene}/time"] = np.array(u.initial_time)
        arrays[f"{scene}/grip"] = u.initial_gripper_xpos
        arrays[f"{scene}/object_z"] = np.array(getattr(u, "height_offset", np.nan))
    arrays["versions"] = np.array([f"mujoco {mujoco.__version__}",
                                   f"gymnasium-robotics {gymnasium_robotics.__version__}"])
    np.savez(path, **arrays)
    print(f"wrote {path} ({path.stat().st_size // 1024} KiB; mujoco {mujoco.__version__})")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=pathlib.Path, default=CLASSIC_STARTS, help=f"where to write ({CLASSIC_STARTS})")
    args = parser.parse_args()
    try:
        import gymnasium_robotics  # noqa: F401
    except ImportError as error:
        print(f"classic_starts: {error}; run it in the virtualenv `python -m benchmarks.parity_v4 --venv DIR` makes",
              file=sys.stderr)
        return 2
    record_starts(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
