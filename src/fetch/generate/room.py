"""The room around an object: how wide the fingers may open before one of them comes down on something
beside it (`finger_room`), and how high a hand passing over it goes (`pass_over`).

A person who grasps a block standing next to a wall opens the hand just enough; a pad's X opens it fully
(5 cm a finger), and carried over to a block beside the bin's wall, that open finger lands on the rim and
the hand stops 5 cm above the block (Bin-place-v2: 9 of a pixel policy's 11 failures in 100 episodes,
docs/generate.md). `finger_room` measures, with MuJoCo's ray casts, how far the nearest other thing is
from the object along the axis the fingers close on, on each side, and gives the opening that puts each
finger in the middle of the gap between the object and that thing: the most a small error of the hand's
place may be, either way, without a finger landing on the object's top or on the wall.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from fetch.tasks.subtasks import Scene

STARTS = ("all", "tight")
"""Which of the env's starts attempts are made from (`generate --starts`, `collect --starts`): every one, or only
the tight ones (`tight_start`)."""
NO_TIGHT_START = 2000
"""With `--starts tight`: skipped starts before the first tight one after which the task is taken to have none."""
WIDEST = 0.05
"""[m] a finger's opening fully open (its travel): how wide a pad's X opens it."""
RAY_STEP = 0.01
"""[m] the height between two rays, from just above the object's bottom to above its top."""
ABOVE = 0.02
"""[m] how far above the object's top the rays reach (a finger comes down past everything lower)."""


def _extent(model: mujoco.MjModel, data: mujoco.MjData, geoms: np.ndarray, origin: np.ndarray,
            direction: np.ndarray) -> float:
    """[m] how far `geoms` reach from `origin` along `direction` (a unit vector), by their bounding boxes."""
    far = -np.inf
    for g in geoms:
        rot = data.geom_xmat[g].reshape(3, 3)
        centre = data.geom_xpos[g] + rot @ model.geom_aabb[g, :3]
        half = float(np.abs(direction @ rot) @ model.geom_aabb[g, 3:])
        far = max(far, float(direction @ (centre - origin)) + half)
    return far


def _free_run(model: mujoco.MjModel, data: mujoco.MjData, start: np.ndarray, direction: np.ndarray, body: int,
              finger: int, reach: float) -> float:
    """[m] how far a ray from `start` along `direction` goes before it meets a geom that is not of `body`
    or of the robot (the bodies with the root of geom `finger`'s) and that a finger would touch (drawn-only
    geoms, the hand's mocap cross or the goal's marker, are passed through); `reach` if nothing is that near."""
    robot = model.body_rootid[model.geom_bodyid[finger]]
    contype, conaffinity = model.geom_contype, model.geom_conaffinity
    geom = np.zeros(1, dtype=np.int32)
    travelled = 0.0
    point = start.copy()
    while travelled < reach:
        distance = mujoco.mj_ray(model, data, point, direction, None, 1, body, geom)
        if distance < 0:
            return reach
        travelled += distance
        g = geom[0]
        touches = (contype[g] & conaffinity[finger]) or (conaffinity[g] & contype[finger])
        if touches and model.body_rootid[model.geom_bodyid[g]] != robot:
            return min(travelled, reach)
        point = start + (travelled + 1e-4) * direction  # through it, on to what is behind it
        travelled += 1e-4
    return reach


def finger_room(model: mujoco.MjModel, data: mujoco.MjData, fingers: tuple[int, int], body: int,
                centre: np.ndarray, hand: np.ndarray, opening: float, widest: float) -> float | None:
    """The opening [m a finger, as `Expert.finger_servo` takes it] at which, with the hand at `hand` [m],
    each finger would come down midway between the object (body `body`, at `centre`) and the nearest
    thing beside it along the fingers' axis, if that is less than `widest`; None if nothing is so near
    that `widest` would put a finger on it, if a finger cannot fit between them at all, or if the hand comes
    down so far off the object's centre that, opened so, the finger on the other side would land on the object.
    `opening` is the fingers' opening now (to relate the fingers' places to the opening)."""
    finger_geoms = [np.flatnonzero(model.geom_bodyid == f) for f in fingers]
    places = [data.geom_xpos[g].mean(axis=0) for g in finger_geoms]
    span = float(np.linalg.norm(places[1] - places[0]))  # between the fingers' centres
    if span < 1e-9:
        return None
    axis = (places[1] - places[0]) / span
    across = np.cross([0.0, 0.0, 1.0], axis)
    if np.linalg.norm(across) < 1e-9:  # fingers one above the other: nothing beside them to measure
        return None
    across /= np.linalg.norm(across)
    at_closed = 0.5 * span - opening  # a finger's centre from the hand's, closed
    thickness = max(_extent(model, data, g, data.geom_xpos[g].mean(axis=0), axis) for g in finger_geoms)
    width = max(_extent(model, data, g, data.geom_xpos[g].mean(axis=0), across) for g in finger_geoms)
    geoms = np.flatnonzero(model.geom_bodyid == body)
    up = np.array([0.0, 0.0, 1.0])
    bottom, top = -_extent(model, data, geoms, centre, -up), _extent(model, data, geoms, centre, up)
    heights = np.arange(bottom + 0.5 * RAY_STEP, top + ABOVE, RAY_STEP)
    finger = int(finger_geoms[0][0])
    offset = float(axis @ (hand - centre))  # where the hand comes down, off the object's centre along the axis
    room, clear = np.inf, 0.0
    for side in (1.0, -1.0):
        direction = side * axis
        face = _extent(model, data, geoms, centre, direction)
        clear = max(clear, face + thickness - at_closed - side * offset)  # the least that misses the object's top
        reach = side * offset + at_closed + widest + thickness  # the outer face of a finger opened `widest`
        nearest = min(_free_run(model, data, centre + h * up + s * across, direction, body, finger, reach)
                      for h in heights for s in (-width, 0.0, width))
        if nearest >= reach:
            continue  # nothing this finger would come down on
        if nearest - face < 2 * thickness:
            return None  # a finger does not fit between them: no opening helps
        room = min(room, 0.5 * (face + nearest) - at_closed - side * offset)
    if not np.isfinite(room) or room < clear:
        return None  # nothing near, or the hand comes down so far off-centre that a finger would land on the object
    return float(room)


def tight_start(env: Any, scene: Scene, opening: float) -> bool:
    """Whether the object of the task's first subtask, as the env (a `FetchEnv`, just reset) has placed it, stands
    so close beside something along the fingers' axis that fully open fingers (`WIDEST`) coming down over its
    centre would land on it: a start where a pad's full opening fails. `opening` [m] is the fingers' opening now
    (the observation's `gripper_state`, averaged); `scene` is `Scene(env.model)`. False where the first subtask
    approaches no loose object (a drawer's handle, a goal in the air)."""
    first = type(env.task).subtasks[0]
    if first.done is None or scene.loose(first.reference) is None:
        return False
    body = int(env.model.site_bodyid[scene.site(first.reference)])
    centre = first.frame(scene, env.data).pos
    return finger_room(env.model, env.data, scene.fingers, body, centre, centre, opening, WIDEST) is not None


def resets_tight(env: Any, seed: int, scene: Scene) -> bool:
    """Reset `env` (a gymnasium env of a `FetchEnv`) with `seed`: whether that start is tight (`tight_start`);
    `scene` is `Scene(env.unwrapped.model)`."""
    obs, _ = env.reset(seed=seed)
    base = env.unwrapped
    return tight_start(base, scene, float(np.mean(obs["observation"][base.observation_layout["gripper_state"]])))


FINGERTIPS = 0.02
"""[m] how far the fingers reach below the grip site (1.85 cm in the robot's model)."""
FINGER_WIDTH = 0.015
"""[m] how far the closed fingers reach sideways from the grip site."""
CLEARANCE = 0.01
"""[m] the gap left between the fingertips and the top of an object the hand passes over."""


def pass_over(path: np.ndarray, centre: np.ndarray, radius: float, height: float) -> None:
    """Lift the steps of `path` (N, 3) [m, world] that pass over a loose object (at `centre`, `radius`
    and `height` [m] its extent) so that the fingertips clear it by `CLEARANCE`, and the steps either
    side of them by half as much; in place. The steps that end the path over the object (coming down
    to grasp it) are left as they are: only passes that leave it again are lifted. A person who goes
    over a block to push it from behind does it with a centimetre to spare; carried over to another
    block and perturbed, the same pass drags the block along, or off the table (docs/generate.md)."""
    over = np.linalg.norm(path[:, :2] - centre[:2], axis=1) < radius + FINGER_WIDTH
    arriving = int(np.argmin(over[::-1])) if not over.all() else len(over)  # the final run over it
    passing = len(over) - arriving
    if not over[:passing].any():
        return
    lift = np.zeros(len(path))
    top = centre[2] + height + FINGERTIPS + CLEARANCE
    lift[:passing] = np.where(over[:passing], np.maximum(top - path[:passing, 2], 0.0), 0.0)
    spread = lift.copy()
    spread[1:passing] = np.maximum(spread[1:passing], 0.5 * lift[:passing - 1])
    spread[:passing - 1] = np.maximum(spread[:passing - 1], 0.5 * lift[1:passing])
    path[:passing, 2] += spread[:passing]
