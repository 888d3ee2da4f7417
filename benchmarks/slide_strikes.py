"""Measure the Slide expert's strike table: how far one strike sends a puck at rest, by where it is.

The arm weakens as it stretches, forwards and sideways: at x = 1.2 m a strike of size 0.7 sends
the puck 29 cm from y = 0.75 m (in front of the shoulder) and 21 cm from y = 0.5 or 1.0 m. So the
table is indexed by the puck's x and by how far across it is from the robot's centre line.

For every grid point (x, |y - 0.75|) and action size, the puck is put there at rest (its joint set
after a reset), the Slide expert lines up and makes one strike of that size (along +x, or along
each diagonal), and the puck's displacement once it stops is recorded: along x, or per axis on a
diagonal; the mean over y = 0.75 +- across and both diagonals. A grid point the hand cannot strike
from counts as 0. Sizes are made non-decreasing (a longer strike never plans a shorter shot).

    .venv/bin/python benchmarks/slide_strikes.py                 # ~3 min, writes the table
    .venv/bin/python benchmarks/slide_strikes.py --out /tmp/t.npz --print
    .venv/bin/python benchmarks/slide_strikes.py --spread 100        # ~6 min: strikes under action noise 0.1

The table ships as src/fetch/assets/slide_strikes.npz; `fetch.experts.slide` reads it.
"""

from __future__ import annotations

import argparse
import pathlib

import gymnasium as gym
import mujoco
import numpy as np

import fetch  # noqa: F401  (registers the ids)
from fetch.experts.base import Stage
from fetch.experts.slide import CENTRE_Y, STRIKE_TABLE
from fetch.timing import CONTROL_DT
from slide_reach import Forced

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


def strike(env: gym.Env, xy: tuple[float, float], line: tuple[float, float], size: float,
           noise: float = 0.0, rng: np.random.Generator | None = None) -> np.ndarray | None:
    """The puck's displacement [m, xy] from one strike from rest at `xy`, or None if the hand
    never got to strike; with `noise`, every action (line-up and strike) gets Gaussian noise of
    that std, as expert_success.py adds it."""
    env.reset(seed=0)
    model, data = env.unwrapped.model, env.unwrapped.data
    joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "object0:joint")
    adr = model.jnt_qposadr[joint]
    data.qpos[adr:adr + 2] = xy
    mujoco.mj_forward(model, data)
    obs = env.step(np.zeros(4, np.float32))[0]
    layout = env.unwrapped.observation_layout
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


SPREAD_FROM = ((1.1, CENTRE_Y), (1.2, CENTRE_Y + 0.15))
"""[m] where the puck rests before the strikes `spread` measures: in front of the shoulder and out to the side."""
SPREAD_SIZES = (0.3, 0.5, 0.7, 0.9)


def spread(trials: int, noise: float, tolerance: float = 0.05) -> None:
    """Print how far strikes of each size land from where the same strike lands without noise,
    under action noise `noise`: what a policy that aims by striking can rely on."""
    env = gym.make("Slide-v2").unwrapped
    rng = np.random.default_rng(0)
    print(f"{trials} strikes per row under action noise {noise} (mujoco {mujoco.__version__}); "
          f"displacements against the same strike without noise\n")
    print(f"| puck at [m] | line | size | without noise [cm] | along: mean / std [cm] | across: std [cm] "
          f"| within {100 * tolerance:.0f} cm of it |")
    print("|---|---|---|---|---|---|---|")
    for xy in SPREAD_FROM:
        for line in ((1.0, 0.0), (1.0, 1.0)):
            unit = np.asarray(line) / np.hypot(*line)
            normal = np.array([-unit[1], unit[0]])
            for size in SPREAD_SIZES:
                plain = strike(env, xy, line, size)
                noisy = [strike(env, xy, line, size, noise, rng) for _ in range(trials)]
                if plain is None:
                    continue
                moved = np.array([m for m in noisy if m is not None])
                along, across = moved @ unit, moved @ normal
                within = np.linalg.norm(moved - plain, axis=1) < tolerance
                print(f"| ({xy[0]:.2f}, {xy[1]:.2f}) | {'x' if line[1] == 0 else 'diagonal'} | {size} "
                      f"| {100 * float(plain @ unit):.1f} | {100 * along.mean():.1f} / {100 * along.std():.1f} "
                      f"| {100 * across.std():.1f} | {within.sum() / trials:.0%} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=pathlib.Path, default=STRIKE_TABLE, help="where to write the table")
    parser.add_argument("--print", action="store_true", help="print the tables")
    parser.add_argument("--spread", type=int, default=0, metavar="TRIALS",
                        help="instead: how far TRIALS noisy strikes of each size land from the noiseless one")
    parser.add_argument("--noise", type=float, default=0.1, help="the action noise's std for --spread")
    args = parser.parse_args()
    if args.spread:
        spread(args.spread, args.noise)
        return
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
