"""Box-open and Box-close: an immovable open box and a loose lid with a handle."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from fetch import observation as ob
from fetch.robot import RobotConfig
from fetch.scene import MUJOCO_SOLIMP, MUJOCO_SOLREF
from fetch.tasks.base import TABLE_TOP, FreeObject, Start, Task, box_geom, mocap_index, object_parts
from fetch.tasks.subtasks import GOAL, Grasped, Lifted, Subtask

BOX = 0.08
"""[m] half the box's outer width (16 x 16 cm)."""
WALL = 0.01
BOX_HEIGHT = 0.06
LID = 0.09
"""[m] half the lid's width: it overhangs the walls by 1 cm on every side."""
LID_THICK = 0.01
HANDLE = (0.02, 0.01, 0.015)
"""[m] half-sizes of the handle on the lid: 4 cm along x, 2 cm across (the fingers close on it), 3 cm tall."""
SEATED_Z = TABLE_TOP + BOX_HEIGHT + LID_THICK / 2
ON_TABLE_Z = TABLE_TOP + LID_THICK / 2
SEAT_XY = 0.02
"""[m] a seated lid's centre is within this of the box's axis (it still covers the opening)."""
SEAT_Z = 0.01
"""[m] ... and within this of the seated height (so it lies flat on the walls)."""
BESIDE = (0.20, 0.24)
"""[m] a lid beside the box has its centre this far from the box's along x or y: >= 3 cm gap."""


def add_box_and_lid(spec: mujoco.MjSpec) -> None:
    """A mocap box (it cannot be pushed around) and a free lid, parked off the table."""
    box = spec.worldbody.add_body(name="box", mocap=True, pos=[1.9, 1.2, TABLE_TOP])
    box_geom(box, "box_floor", [BOX, BOX, 0.005], [0, 0, 0.005], "box_mat")
    half_h = BOX_HEIGHT / 2
    for i, (x, y) in enumerate([(1, 0), (-1, 0), (0, 1), (0, -1)]):
        half = [WALL / 2, BOX, half_h] if x else [BOX, WALL / 2, half_h]
        box_geom(box, f"box_wall{i}", half, [x * (BOX - WALL / 2), y * (BOX - WALL / 2), half_h], "box_mat")
    box.add_site(name="box", size=[0.01, 0.01, 0.01], rgba=[0, 0, 0, 0])
    lid = spec.worldbody.add_body(name="lid", pos=[1.9, 1.5, ON_TABLE_Z])
    lid.add_freejoint(name="lid:joint")
    # The lid keeps MuJoCo's default contacts, not the room's stiff ones (fetch.scene.ROOM_SOLREF):
    # with stiff contacts on both sides, the thin light plate pressed between the fingers and a wall
    # made the simulation unstable under abuse (it flew off at hundreds of m/s; bench_abuse.py).
    soft = {"solref": list(MUJOCO_SOLREF), "solimp": list(MUJOCO_SOLIMP)}
    box_geom(lid, "lid", [LID, LID, LID_THICK / 2], [0, 0, 0], "lid_mat", mass=0.3, condim=4, **soft)
    box_geom(lid, "lid_handle", list(HANDLE), [0, 0, LID_THICK / 2 + HANDLE[2]], "handle_mat",
             mass=0.05, condim=4, **soft)
    lid.add_site(name="lid", size=[0.01, 0.01, 0.01], rgba=[0, 0, 0, 0])


def seated(lid: np.ndarray, seat: np.ndarray) -> np.ndarray:
    """Vectorised: the lid at `lid` covers a box whose seated-lid position is `seat`."""
    lid, seat = np.asarray(lid, np.float64), np.asarray(seat, np.float64)
    dxy = np.linalg.norm(lid[..., :2] - seat[..., :2], axis=-1)
    return (dxy < SEAT_XY) & (np.abs(lid[..., 2] - seat[..., 2]) < SEAT_Z)


def seated_at(lid: list[float], seat: list[float]) -> bool:
    """`seated` for one lid, in scalar math."""
    return math.hypot(lid[0] - seat[0], lid[1] - seat[1]) < SEAT_XY and abs(lid[2] - seat[2]) < SEAT_Z


class _BoxTask(Task):
    robot = RobotConfig(start_height=0.22)
    parts = (*object_parts("lid", "lid"), ob.site_pos("box_pos", "box"))
    achieved = "lid_pos"
    success_rule = "lid within 5 cm of the goal"
    subtasks = (Subtask("grasp", "lid", Grasped("lid")),
                Subtask("lift", "lid", Lifted("lid", "lid", SEATED_Z + 0.02)),
                Subtask("place", GOAL, None))
    box_range = 0.08
    """[m] the box's centre is sampled this far (x and y) around the gripper's start."""

    def build(self, spec: mujoco.MjSpec) -> None:
        add_box_and_lid(spec)

    def bind(self, model: mujoco.MjModel) -> None:
        self.lid = FreeObject(model, "lid")
        self.box_mocap = mocap_index(model, "box")
        layout = ob.layout(self.parts)
        self._lid_pos, self._box_pos = layout["lid_pos"], layout["box_pos"]

    def place_box(self, data: mujoco.MjData, rng: np.random.Generator, grip_start: np.ndarray) -> np.ndarray:
        center = grip_start[:2] + rng.uniform(-self.box_range, self.box_range, size=2)
        data.mocap_pos[self.box_mocap] = (center[0], center[1], TABLE_TOP)
        return center

    def facts(self, data: mujoco.MjData, obs: np.ndarray) -> dict[str, float]:
        bx, by, _ = obs[self._box_pos].tolist()
        return {"lid_seated": 1.0 if seated_at(obs[self._lid_pos].tolist(), [bx, by, SEATED_Z]) else 0.0}


def spot_beside(rng: np.random.Generator, box_center: np.ndarray, table_low: tuple[float, float],
                table_high: tuple[float, float]) -> np.ndarray:
    """A lid position on the table beside the box: along +-x or +-y, clear of it, on the table."""
    for _ in range(1000):
        axis = int(rng.integers(2))
        offset = np.zeros(2)
        offset[axis] = rng.choice([-1.0, 1.0]) * rng.uniform(*BESIDE)
        offset[1 - axis] = rng.uniform(-0.04, 0.04)
        xy = box_center + offset
        if np.all(xy - LID >= table_low) and np.all(xy + LID <= table_high):
            return np.array([xy[0], xy[1], ON_TABLE_Z])
    raise RuntimeError("no spot beside the box on the table; the box range is inconsistent")


# The part of the table the lid may rest on: its top minus a margin, and no nearer the robot
# than x = 1.10 (comfortably inside the arm's reach).
_TABLE_LOW, _TABLE_HIGH = (1.10, 0.42), (1.53, 1.08)


class BoxOpen(_BoxTask):
    """Take the lid off the box and set it down on the table at the goal beside the box."""

    name = "box_open"
    instruction = "take the lid off the box and set it down beside the box"
    expert = "fetch.experts:box_open"

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              start: Start) -> np.ndarray:
        center = self.place_box(data, rng, start.grip)
        self.lid.place(data, np.array([center[0], center[1], SEATED_Z]))
        return spot_beside(rng, center, _TABLE_LOW, _TABLE_HIGH)


class BoxClose(_BoxTask):
    """Put the lid, lying on the table beside the box, onto the box.

    Success is "seated": the lid's centre within 2 cm (xy) of the box's axis and within 1 cm of
    the seated height, which means it lies flat on the walls and covers the opening.
    """

    name = "box_close"
    instruction = "put the lid on the box"
    expert = "fetch.experts:box_close"
    success_rule = "lid seated: its centre within 2 cm (xy) of the box's axis and 1 cm of the seated height"

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              start: Start) -> np.ndarray:
        center = self.place_box(data, rng, start.grip)
        self.lid.place(data, spot_beside(rng, center, _TABLE_LOW, _TABLE_HIGH))
        return np.array([center[0], center[1], SEATED_Z])

    def is_success(self, achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        return seated(achieved, desired).astype(np.float64)

    def success(self, achieved: list[float], desired: list[float], distance: float) -> bool:
        return seated_at(achieved, desired)
