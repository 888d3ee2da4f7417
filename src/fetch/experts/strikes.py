"""How a puck glides on Slide's table, and how far a strike sends it: the physics the Slide expert
plans with (`fetch.experts.slide`), measured on Fetch*-v4's Slide table (friction 0.1, MuJoCo's
default pyramidal friction cone).

- Friction on the table is not isotropic. A gliding puck decelerates at `DECELERATION` along the
  larger of its x and y velocity components only, the smaller one kept, until both are equal;
  then both at half that. From a launch (A, B), A >= B >= 0, it comes to rest (A^2 + B^2) / 2a
  further along A's axis and A B / a along B's (`glide`): a glide along an axis stays on it, any
  other bends towards the nearest diagonal, where it stays.
- A strike is `STRIKE_STEPS` steps of one action: the mocap target jumps by 5 cm a step at full
  size and the hand surges, so the puck leaves at up to ~1 m/s, faster than the hand ever moves
  steadily. How far it then goes is measured against the action's size, the puck's x and how far
  across it is from the robot's centre line, for each line (x, diagonal, y outwards, y inwards: the
  arm weakens as it stretches, forwards or sideways, and strikes nothing beyond x ~ 1.39 m):
  `STRIKE_TABLE`, read by `strike_size` and `strike_reach`.
"""

from __future__ import annotations

import functools
import pathlib

import numpy as np

DECELERATION = 0.98
"""[m/s^2] a puck gliding along an axis decelerates this much (friction 0.1 times g)."""
RADIUS = 0.025
"""[m] the puck's radius."""
STRIKE_STEPS = 2
"""[steps] a strike is this many steps of one action, from rest 1 cm behind the puck."""
STRIKE_TABLE = pathlib.Path(__file__).resolve().parent.parent / "assets" / "slide_strikes.npz"
"""How far a strike of each action size sends a puck at rest, by the puck's x and its distance
across from the robot's centre line (the arm weakens as it stretches either way); measured and written by
tools/slide_strikes.py (`python -m tools.slide_strikes`)."""
CENTRE_Y = 0.75
"""[m] the y of the robot's centre line (its shoulder)."""

@functools.cache
def _strikes() -> dict[str, np.ndarray]:
    with np.load(STRIKE_TABLE) as table:
        return {name: table[name] for name in table.files}


def is_diagonal(line: np.ndarray) -> bool:
    return bool(line[0] != 0.0 and line[1] != 0.0)


def _strike_table(puck: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sizes, [m] how far a strike of each size along `line` sends a puck at rest at `puck` [m, xy],
    per axis on a diagonal): the measured table interpolated in x and across. Along y the side face
    strikes harder towards the centre line than away from it, so each way has its table."""
    table = _strikes()
    x, off = float(puck[0]), float(puck[1]) - CENTRE_Y
    if is_diagonal(line):
        rows = table["along_diagonal"]
    elif line[0] != 0.0:
        rows = table["along_x"]
    else:
        rows = table["along_y_out" if line[1] * off >= 0.0 else "along_y_in"]
    xs, across = table["xs"], table["across"]
    i = int(np.clip(np.searchsorted(xs, x) - 1, 0, len(xs) - 2))
    j = int(np.clip(np.searchsorted(across, abs(off)) - 1, 0, len(across) - 2))
    u = float(np.clip((x - xs[i]) / (xs[i + 1] - xs[i]), 0.0, 1.0))
    v = float(np.clip((abs(off) - across[j]) / (across[j + 1] - across[j]), 0.0, 1.0))
    reach = ((1 - u) * (1 - v) * rows[i, j] + u * (1 - v) * rows[i + 1, j]
             + (1 - u) * v * rows[i, j + 1] + u * v * rows[i + 1, j + 1])
    return table["sizes"], reach


def strike_size(distance: float, puck: np.ndarray, line: np.ndarray) -> float:
    """The action size whose strike along `line` (xy) sends a puck at rest at `puck` [m, xy]
    `distance` [m] before it stops; if that is beyond any strike, the smallest size that strikes
    furthest."""
    per_axis = distance / np.sqrt(2.0) if is_diagonal(line) else distance
    sizes, reach = _strike_table(puck, line)
    # Where the table stops growing (a harder strike sent the puck no further) it strikes no harder.
    top = int(np.argmax(reach >= reach[-1])) + 1
    return float(np.interp(per_axis, reach[:top], sizes[:top]))


def strike_reach(puck: np.ndarray, line: np.ndarray) -> float:
    """[m] the furthest a strike along `line` (xy) sends a puck at rest at `puck` [m, xy]."""
    furthest = float(_strike_table(puck, line)[1][-1])
    return furthest * np.sqrt(2.0) if is_diagonal(line) else furthest


def glide_time(distance: float, diagonal: bool, short: float = 0.0) -> float:
    """[s] how long a puck struck to glide `distance` [m] (along an axis or the diagonal) takes to
    come within `short` [m] of where it stops."""
    distance, short = max(distance, 0.0), min(max(short, 0.0), max(distance, 0.0))
    if diagonal:  # each axis decelerates at half the rate, over 1 / sqrt(2) of the distance
        return 2.0 * float(np.sqrt(DECELERATION * distance / np.sqrt(2.0))
                           - np.sqrt(DECELERATION * short / np.sqrt(2.0))) / DECELERATION
    return float(np.sqrt(2.0 * DECELERATION * distance) - np.sqrt(2.0 * DECELERATION * short)) / DECELERATION


def glide(velocity: np.ndarray) -> np.ndarray:
    """[m] where a puck moving at `velocity` [m/s, world xy] comes to rest, from where it is."""
    a, b = abs(float(velocity[0])), abs(float(velocity[1]))
    major, minor = (a * a + b * b) / (2.0 * DECELERATION), a * b / DECELERATION
    rest = np.array([major, minor]) if a >= b else np.array([minor, major])
    return rest * np.sign(velocity[:2])


def launch(displacement: np.ndarray) -> np.ndarray:
    """[m/s] the velocity whose glide ends `displacement` [m, world xy] away (`glide`'s inverse)."""
    x, y = abs(float(displacement[0])), abs(float(displacement[1]))
    s = np.sqrt(2.0 * DECELERATION * (x + y))
    t = np.sqrt(2.0 * DECELERATION * abs(x - y))
    major, minor = (s + t) / 2.0, (s - t) / 2.0
    speed = np.array([major, minor]) if x >= y else np.array([minor, major])
    return speed * np.where(np.asarray(displacement[:2]) < 0, -1.0, 1.0)
