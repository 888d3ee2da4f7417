"""Write src/fetch/assets/slide_strikes.npz: how far one strike sends a puck at rest, by where it is.

The Slide expert plans its strikes from this table (`fetch.experts.strikes` reads it). The arm weakens
as it stretches, forwards and sideways: at x = 1.2 m a strike of size 0.7 sends the puck 29 cm from
y = 0.75 m (in front of the shoulder) and 21 cm from y = 0.5 or 1.0 m. So the table is indexed by the
puck's x and by how far across it is from the robot's centre line.

For every grid point (x, |y - 0.75|) and action size, the puck is put there at rest (its joint set
after a reset), the Slide expert lines up and makes one strike of that size (along +x, or along
each diagonal), and the puck's displacement once it stops is recorded: along x, or per axis on a
diagonal; the mean over y = 0.75 +- across and both diagonals. A grid point the hand cannot strike
from counts as 0. Sizes are made non-decreasing (a longer strike never plans a shorter shot).

    .venv/bin/python -m tools.slide_strikes                       # ~8 min, writes the package's table
    .venv/bin/python -m tools.slide_strikes --out /tmp/t.npz --print

(from the repository root). How far noisy strikes land from this table: `python -m experiments.slide_spread`."""

from __future__ import annotations

import argparse
import pathlib
from collections.abc import Mapping

import gymnasium as gym
import mujoco
import numpy as np

import fetch  # noqa: F401  (registers the ids)
from fetch.experts.base import Stage
from fetch.experts.slide import Slide
from fetch.experts.strikes import CENTRE_Y, STRIKE_TABLE
from fetch.timing import CONTROL_DT

XS = (0.9, 0.95, 1.0, 1.05, 1.1, 1.15, 1.2, 1.25, 1.3, 1.33, 1.36, 1.39, 1.42)
"""[m] the puck's x."""
ACROSS = (0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3)
"""[m] the puck's distance across from the robot's centre line, |y - CENTRE_Y|."""
SIZES = (0.15, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
"""the strike's action size."""
TABLES = ("along_x", "along_diagonal", "along_y_out", "along_y_in")
"""A strike along x (one fingertip), along a diagonal (the fingers' corner), and along y (a side
face) away from the centre line or towards it (the arm pushes harder inwards)."""
SETTLE_STEPS = 150
"""[steps] at most this long for the line-up, the strike and the glide."""
CLEAR, LIFT_STEPS = 0.05, 4
"""[m, steps] a puck put this close to where the hand starts (x = 1.0 m on the centre line) would sit on the
fingers, which carry it off the table on mujoco 4.0.1: the hand is lifted this many steps first."""


class Forced(Slide):
    """The Slide expert made to strike along given lines with given action sizes, then stop."""

    def __init__(self, layout: Mapping[str, slice], strikes: list[tuple[tuple[float, float], float]]) -> None:
        self.strikes = list(strikes)
        super().__init__(layout)

    def reset(self) -> None:
        super().reset()
        self.queue = list(self.strikes)
        self.forced_size = 0.0

    def plan(self, rest: np.ndarray, goal: np.ndarray, grip: np.ndarray) -> None:
        if self.stage is Stage.LINE_UP:
            return
        if not self.queue:
            self.finish(grip, goal)
            return
        (lx, ly), self.forced_size = self.queue.pop(0)
        self.line = np.array([lx, ly]) / np.hypot(lx, ly)
        self.target = goal[:2].copy()
        self.motion, self.offset = self.contact(self.line)
        self.advance(Stage.LINE_UP)

    def size(self, distance: float, puck: np.ndarray) -> float:
        # A negative size scales the expert's own choice (its strike table) by minus that.
        if self.forced_size < 0.0:
            return min(-self.forced_size * super().size(distance, puck), 1.0)
        return self.forced_size


def strike(env: gym.Env, xy: tuple[float, float], line: tuple[float, float], size: float,
           noise: float = 0.0, rng: np.random.Generator | None = None) -> np.ndarray | None:
    """The puck's displacement [m, xy] from one strike from rest at `xy`, or None if the hand
    never got to strike; with `noise`, every action (line-up and strike) gets Gaussian noise of
    that std, as benchmarks/expert_success.py adds it."""
    obs = env.reset(seed=0)[0]
    layout = env.unwrapped.observation_layout
    if np.linalg.norm(obs["observation"][layout["grip_pos"]][:2] - xy) < CLEAR:
        for _ in range(LIFT_STEPS):  # the puck would be put on the fingers, and carried off the table
            env.step(np.float32([0.0, 0.0, 1.0, 0.0]))
    model, data = env.unwrapped.model, env.unwrapped.data
    joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "object0:joint")
    adr = model.jnt_qposadr[joint]
    data.qpos[adr:adr + 2] = xy
    mujoco.mj_forward(model, data)
    obs = env.step(np.zeros(4, np.float32))[0]
    expert = Forced(layout, [(line, size)])
    before, struck_at = None, 0
    for step in range(SETTLE_STEPS):
        action = expert(obs)
        if expert.stage is Stage.PUSH and before is None:
            before, struck_at = obs["observation"][layout["object_pos"]][:2].copy(), step
        if noise and rng is not None:
            action = action + rng.normal(0.0, noise, size=4).astype(np.float32)
        obs = env.step(action)[0]
        speed = np.linalg.norm(obs["observation"][layout["object_velp"]][:2]) / CONTROL_DT
        if before is not None and step > struck_at + 4 and speed < 0.003:
            break
    if before is None:
        return None
    return obs["observation"][layout["object_pos"]][:2] - before


def _runs(kind: str, across: float) -> list[tuple[float, tuple[float, float]]]:
    """(the puck's y offset from the centre line, line) of each strike one table entry averages."""
    sides = (1.0, -1.0) if across else (1.0,)
    if kind == "along_x":
        return [(side * across, (1.0, 0.0)) for side in sides]
    if kind == "along_diagonal":
        return [(side * across, line) for side in sides for line in ((1.0, 1.0), (1.0, -1.0))]
    outward = kind == "along_y_out"
    if not across:
        return [(0.0, (0.0, 1.0)), (0.0, (0.0, -1.0))]
    return [(side * across, (0.0, side if outward else -side)) for side in sides]


def measure(kind: str) -> np.ndarray:
    """[m] table[x, across, size] of one kind of strike (`TABLES`): the distance along its line,
    per axis on a diagonal."""
    env = gym.make("Slide-v2").unwrapped
    table = np.zeros((len(XS), len(ACROSS), len(SIZES)))
    for i, x in enumerate(XS):
        for j, across in enumerate(ACROSS):
            for k, size in enumerate(SIZES):
                runs = []
                for off, line in _runs(kind, across):
                    moved = strike(env, (x, CENTRE_Y + off), line, size)
                    along = 0.0 if moved is None else float(moved @ np.asarray(line)) / float(np.hypot(*line))
                    runs.append(max(along / np.sqrt(2.0) if kind == "along_diagonal" else along, 0.0))
                table[i, j, k] = np.mean(runs)
    return np.maximum.accumulate(np.round(table, 3), axis=2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=pathlib.Path, default=STRIKE_TABLE, help="where to write the table")
    parser.add_argument("--print", action="store_true", help="print the tables")
    args = parser.parse_args()
    tables = {kind: measure(kind) for kind in TABLES}
    np.savez(args.out, xs=np.array(XS), across=np.array(ACROSS), sizes=np.array(SIZES), **tables)
    print(f"wrote {args.out} (mujoco {mujoco.__version__})")
    if args.print:
        for name, table in tables.items():
            print(f"\n{name} [m]: rows x, across; columns sizes {SIZES}")
            for i, x in enumerate(XS):
                for j, across in enumerate(ACROSS):
                    print(f"x {x:.2f} across {across:.2f}: " + " ".join(f"{v:.3f}" for v in table[i, j]))


if __name__ == "__main__":
    main()
