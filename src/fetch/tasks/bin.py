"""Bin-pick and Bin-place: a 5 cm block and an open bin on the table."""

from __future__ import annotations

import mujoco
import numpy as np

from fetch import observation as ob
from fetch.robot import RobotConfig
from fetch.tasks.base import (
    DISTANCE_THRESHOLD,
    TABLE_TOP,
    FreeObject,
    Start,
    Task,
    box_geom,
    goal_distance,
    mocap_index,
    object_parts,
)
from fetch.tasks.subtasks import GOAL, Grasped, Lifted, Subtask

INNER = 0.10
"""[m] half the bin's inner width (a 20 x 20 cm floor)."""
WALL = 0.01
"""[m] wall thickness."""
WALL_HEIGHT = 0.06
"""[m] height of the rim above the table."""
FLOOR = 0.01
"""[m] floor thickness: the block rests at TABLE_TOP + FLOOR + BLOCK."""
BLOCK = 0.025
"""[m] half the block's edge."""
OUTER = INNER + WALL
REST_IN_BIN = TABLE_TOP + FLOOR + BLOCK
REST_ON_TABLE = TABLE_TOP + BLOCK
RIM_ABOVE_REST = TABLE_TOP + WALL_HEIGHT - REST_IN_BIN
"""[m] how far the rim is above a resting block's centre."""


def add_bin_and_block(spec: mujoco.MjSpec) -> None:
    """A mocap bin (immovable; moved at reset) and a free block, both parked off the table."""
    bin_ = spec.worldbody.add_body(name="bin", mocap=True, pos=[1.9, 0.2, TABLE_TOP])
    box_geom(bin_, "bin_floor", [OUTER, OUTER, FLOOR / 2], [0, 0, FLOOR / 2], "bin_mat")
    half_h = WALL_HEIGHT / 2
    for i, (x, y) in enumerate([(1, 0), (-1, 0), (0, 1), (0, -1)]):
        half = [WALL / 2, OUTER, half_h] if x else [OUTER, WALL / 2, half_h]
        box_geom(bin_, f"bin_wall{i}", half, [x * (INNER + WALL / 2), y * (INNER + WALL / 2), half_h],
                 "bin_mat")
    bin_.add_site(name="bin", size=[0.01, 0.01, 0.01], rgba=[0, 0, 0, 0])
    block = spec.worldbody.add_body(name="block", pos=[1.9, 0.6, REST_ON_TABLE])
    block.add_freejoint(name="block:joint")
    box_geom(block, "block", [BLOCK] * 3, [0, 0, 0], "object_mat", mass=2.0, condim=3)
    block.add_site(name="block", size=[0.01, 0.01, 0.01], rgba=[0, 0, 0, 0])


class _BinTask(Task):
    robot = RobotConfig(start_height=0.2)
    parts = (*object_parts("block", "block"), ob.site_pos("bin_pos", "bin"))
    achieved = "block_pos"
    success_rule = "block within 5 cm of the goal"
    subtasks = (Subtask("grasp", "block", Grasped("block")),
                Subtask("lift", "block", Lifted("block", "block", TABLE_TOP + WALL_HEIGHT + BLOCK + 0.01)),
                Subtask("place", GOAL, None))
    bin_range = 0.10
    """[m] the bin's centre is sampled this far (x and y) around the gripper's start."""

    def build(self, spec: mujoco.MjSpec) -> None:
        add_bin_and_block(spec)

    def bind(self, model: mujoco.MjModel) -> None:
        self.block = FreeObject(model, "block")
        self.bin_mocap = mocap_index(model, "bin")
        layout = ob.layout(self.parts)
        self._block_pos, self._bin_pos = layout["block_pos"], layout["bin_pos"]

    def place_bin(self, data: mujoco.MjData, rng: np.random.Generator, grip_start: np.ndarray) -> np.ndarray:
        center = grip_start[:2] + rng.uniform(-self.bin_range, self.bin_range, size=2)
        data.mocap_pos[self.bin_mocap] = (center[0], center[1], TABLE_TOP)
        return center

    def facts(self, data: mujoco.MjData, obs: np.ndarray) -> dict[str, float]:
        inside = block_in_bin(obs[self._block_pos].tolist(), obs[self._bin_pos].tolist())
        return {"block_in_bin": 1.0 if inside else 0.0}


def block_in_bin(block: list[float], bin_pos: list[float]) -> bool:
    """The block's centre is over the bin's floor, below its rim."""
    dx, dy = abs(block[0] - bin_pos[0]), abs(block[1] - bin_pos[1])
    return dx < INNER and dy < INNER and block[2] < TABLE_TOP + WALL_HEIGHT


def outside_footprint(rng: np.random.Generator, around: np.ndarray, half_range: float,
                      bin_center: np.ndarray, clearance: float) -> np.ndarray:
    """An xy point around `around` whose square distance from the bin is at least `clearance`."""
    for _ in range(1000):
        xy = around[:2] + rng.uniform(-half_range, half_range, size=2)
        if max(abs(xy[0] - bin_center[0]), abs(xy[1] - bin_center[1])) >= OUTER + clearance:
            return xy
    raise RuntimeError("no spot outside the bin; the bin and spawn ranges are inconsistent")


class BinPick(_BinTask):
    """Pick the block out of the bin and bring it to a goal outside it (table or air)."""

    name = "bin_pick"
    instruction = "pick the block out of the bin and bring it to the goal"
    expert = "fetch.experts:bin_pick"
    spawn_range = 0.04
    """[m] the block's start around the bin's centre: >= 3.5 cm from every wall."""
    goal_range = 0.20
    """[m] around the gripper's start: wider than the classic 0.15 so that a 20 cm bin near
    the middle leaves room for goals outside it."""
    max_goal_height = 0.25

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              start: Start) -> np.ndarray:
        center = self.place_bin(data, rng, start.grip)
        xy = center + rng.uniform(-self.spawn_range, self.spawn_range, size=2)
        self.block.place(data, np.array([xy[0], xy[1], REST_IN_BIN]))
        goal_xy = outside_footprint(rng, start.grip, self.goal_range, center, BLOCK + 0.02)
        height = REST_ON_TABLE
        if rng.uniform() < 0.5:
            height += rng.uniform(0.0, self.max_goal_height)
        return np.array([goal_xy[0], goal_xy[1], height])


class BinPlace(_BinTask):
    """Put the block from the table into the bin, resting on its floor at the goal spot."""

    name = "bin_place"
    instruction = "put the block into the bin"
    expert = "fetch.experts:bin_place"
    success_rule = "block within 5 cm of the goal and its centre below the bin's rim"
    spawn_range = 0.20
    """[m] the block's start around the gripper's (outside the bin); see BinPick.goal_range."""
    goal_range = 0.05
    """[m] the goal around the bin's centre: a block there is >= 2.5 cm from every wall."""

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator,
              start: Start) -> np.ndarray:
        center = self.place_bin(data, rng, start.grip)
        xy = outside_footprint(rng, start.grip, self.spawn_range, center, BLOCK + 0.02)
        self.block.place(data, np.array([xy[0], xy[1], REST_ON_TABLE]))
        goal_xy = center + rng.uniform(-self.goal_range, self.goal_range, size=2)
        return np.array([goal_xy[0], goal_xy[1], REST_IN_BIN])

    # Within 5 cm of a goal on the floor, with its centre below the rim: the block is inside
    # the bin (a goal is >= 5 cm inside the walls). Both tests read only the goal vectors, so
    # HER relabelling works.
    def is_success(self, achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        achieved, desired = np.asarray(achieved, np.float64), np.asarray(desired, np.float64)
        near = goal_distance(achieved, desired) < DISTANCE_THRESHOLD
        low = achieved[..., 2] - desired[..., 2] < RIM_ABOVE_REST
        return (near & low).astype(np.float64)

    def success(self, achieved: list[float], desired: list[float], distance: float) -> bool:
        return distance < DISTANCE_THRESHOLD and achieved[2] - desired[2] < RIM_ABOVE_REST
