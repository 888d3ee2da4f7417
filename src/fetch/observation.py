"""Observations declared as named parts read from MuJoCo sensors, computed as one matrix product.

A task lists its parts (`grip_pos`, `block_rel_pos`, ...). Each part is made of components, each
a sensor reading (optionally minus another, times a scale). The env adds one sensor per distinct
reading to the model; after a step MuJoCo fills `sensordata`, and the observation vector is
`matrix @ sensordata`, plus Euler angles for the parts that are rotations.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import NamedTuple

import mujoco
import numpy as np

from fetch.timing import CONTROL_DT

_EPS4 = float(np.finfo(np.float64).eps) * 4.0

_SENSOR_TYPES = {
    "framepos": (mujoco.mjtSensor.mjSENS_FRAMEPOS, mujoco.mjtObj.mjOBJ_SITE, 3),
    "framequat": (mujoco.mjtSensor.mjSENS_FRAMEQUAT, mujoco.mjtObj.mjOBJ_SITE, 4),
    "framelinvel": (mujoco.mjtSensor.mjSENS_FRAMELINVEL, mujoco.mjtObj.mjOBJ_SITE, 3),
    "frameangvel": (mujoco.mjtSensor.mjSENS_FRAMEANGVEL, mujoco.mjtObj.mjOBJ_SITE, 3),
    "jointpos": (mujoco.mjtSensor.mjSENS_JOINTPOS, mujoco.mjtObj.mjOBJ_JOINT, 1),
    "jointvel": (mujoco.mjtSensor.mjSENS_JOINTVEL, mujoco.mjtObj.mjOBJ_JOINT, 1),
}


@dataclasses.dataclass(frozen=True)
class Reading:
    """One sensor: `kind` (a key of _SENSOR_TYPES) of the site or joint called `target`."""

    kind: str
    target: str

    @property
    def sensor_name(self) -> str:
        return f"obs:{self.kind}:{self.target}"

    @property
    def size(self) -> int:
        return _SENSOR_TYPES[self.kind][2]


@dataclasses.dataclass(frozen=True)
class Component:
    """scale * (reading - minus)."""

    reading: Reading
    scale: float = 1.0
    minus: Reading | None = None


@dataclasses.dataclass(frozen=True)
class Part:
    """A named slice of the observation: its components side by side, or Euler angles of a quat."""

    name: str
    components: tuple[Component, ...]
    euler: bool = False

    @property
    def size(self) -> int:
        return 3 if self.euler else sum(c.reading.size for c in self.components)


def site_pos(name: str, site: str) -> Part:
    """[m] a site's world position."""
    return Part(name, (Component(Reading("framepos", site)),))


def rel_pos(name: str, site: str, ref: str) -> Part:
    """[m] a site's position minus a reference site's, world axes."""
    return Part(name, (Component(Reading("framepos", site), minus=Reading("framepos", ref)),))


def linvel(name: str, site: str, ref: str | None = None) -> Part:
    """[m/step] a site's linear velocity (minus the reference's) times dt, world axes."""
    minus = Reading("framelinvel", ref) if ref else None
    return Part(name, (Component(Reading("framelinvel", site), CONTROL_DT, minus),))


def angvel(name: str, site: str) -> Part:
    """[rad/step] a site's angular velocity times dt, world axes."""
    return Part(name, (Component(Reading("frameangvel", site), CONTROL_DT),))


def euler(name: str, site: str) -> Part:
    """[rad] a site's orientation as Euler angles (the classic suite's convention)."""
    return Part(name, (Component(Reading("framequat", site)),), euler=True)


def joints(name: str, names: tuple[str, ...], velocity: bool = False) -> Part:
    """Joint positions [m or rad], or velocities times dt."""
    kind, scale = ("jointvel", CONTROL_DT) if velocity else ("jointpos", 1.0)
    return Part(name, tuple(Component(Reading(kind, j), scale) for j in names))


def layout(parts: tuple[Part, ...]) -> dict[str, slice]:
    """Each part's slice of the observation vector."""
    out, start = {}, 0
    for part in parts:
        out[part.name] = slice(start, start + part.size)
        start += part.size
    return out


class Mirror(NamedTuple):
    """A reflection of observation vectors in a vertical x-z plane (y -> 2 * plane - y), as order,
    sign and offset arrays: `mirrored = x[..., order] * sign + offset`."""

    order: np.ndarray
    sign: np.ndarray
    offset: np.ndarray

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return x[..., self.order] * self.sign + self.offset


_MIRROR_SIGNS = {"framelinvel": (1.0, -1.0, 1.0), "frameangvel": (-1.0, 1.0, -1.0)}
"""Velocities flip their y; an angular velocity is a pseudovector, so its x and z flip instead."""


def mirror(parts: tuple[Part, ...], plane: float, pairs: Mapping[str, str]) -> Mirror:
    """The reflection of the observation of `parts` in the plane y = `plane` [m, world]: positions
    reflect, relative positions and velocities flip their y, rotations (Euler angles) and angular
    velocities their x and z, and each joint reading swaps with its mirror image's (`pairs`, both
    ways, e.g. the left and right finger), which must be in the same part."""
    size = sum(p.size for p in parts)
    order, sign, offset = np.arange(size), np.ones(size), np.zeros(size)
    for part, where in zip(parts, layout(parts).values(), strict=True):
        if part.euler:
            sign[where] = (-1.0, 1.0, -1.0)
            continue
        row = where.start
        names = [c.reading.target for c in part.components]
        for comp in part.components:
            kind = comp.reading.kind
            if kind in _MIRROR_SIGNS:
                sign[row:row + 3] = _MIRROR_SIGNS[kind]
            elif kind == "framepos":
                sign[row + 1] = -1.0
                offset[row + 1] = 0.0 if comp.minus is not None else 2.0 * plane
            else:  # one joint's reading
                partner = pairs.get(comp.reading.target)
                if partner not in names:
                    raise ValueError(f"part {part.name!r} reads joint {comp.reading.target!r}, whose mirror "
                                     f"image is not in the part (pairs: {dict(pairs)})")
                order[row] = where.start + names.index(partner)
            row += comp.reading.size
    return Mirror(order, sign, offset)


def readings(parts: tuple[Part, ...]) -> list[Reading]:
    """The distinct sensors the parts read, in first-use order."""
    seen: dict[Reading, None] = {}
    for part in parts:
        for comp in part.components:
            seen[comp.reading] = None
            if comp.minus is not None:
                seen[comp.minus] = None
    return list(seen)


def add_sensors(spec: mujoco.MjSpec, parts: tuple[Part, ...]) -> None:
    """Add one sensor per distinct reading to the model."""
    for reading in readings(parts):
        sensor_type, obj_type, _ = _SENSOR_TYPES[reading.kind]
        spec.add_sensor(name=reading.sensor_name, type=sensor_type, objtype=obj_type,
                        objname=reading.target)


class Observer:
    """Computes the observation vector of compiled parts from `data.sensordata`."""

    def __init__(self, model: mujoco.MjModel, parts: tuple[Part, ...]) -> None:
        self.layout = layout(parts)
        size = sum(p.size for p in parts)
        self.size = size

        def adr(reading: Reading) -> int:
            return int(model.sensor(reading.sensor_name).adr[0])

        matrix = np.zeros((size, model.nsensordata))
        self._euler: list[tuple[int, int]] = []
        for part in parts:
            row = self.layout[part.name].start
            if part.euler:
                self._euler.append((row, adr(part.components[0].reading)))
                continue
            for comp in part.components:
                k = comp.reading.size
                cols = adr(comp.reading)
                matrix[row:row + k, cols:cols + k] += comp.scale * np.eye(k)
                if comp.minus is not None:
                    cols = adr(comp.minus)
                    matrix[row:row + k, cols:cols + k] -= comp.scale * np.eye(k)
                row += k
        self._matrix = matrix

    def __call__(self, data: mujoco.MjData) -> np.ndarray:
        """A fresh observation vector (sensors must be current)."""
        sensordata = data.sensordata
        obs = self._matrix @ sensordata
        for row, adr in self._euler:
            obs[row:row + 3] = quat2euler(sensordata[adr:adr + 4].tolist())
        return obs

    def batch(self, sensordata: np.ndarray) -> np.ndarray:
        """`__call__` for many worlds (`fetch.vector`): sensordata rows (worlds, nsensordata) to
        observation rows (worlds, size), each bit for bit what `__call__` gives for that row.

        A stacked matmul is one matrix-vector product per row, as `__call__` does; one matrix
        product (`rows @ matrix.T`) would sum in another order and differ in the last bit. The
        Euler angles stay per row: `quat2euler` uses `math.hypot`, which numpy does not reproduce."""
        rows = np.ascontiguousarray(sensordata, dtype=np.float64)
        obs = np.matmul(self._matrix, rows[:, :, None])[:, :, 0]
        for row, adr in self._euler:
            obs[:, row:row + 3] = [quat2euler(q) for q in rows[:, adr:adr + 4].tolist()]
        return obs


def quat2euler(quat: list[float]) -> list[float]:
    """Euler angles [rad] of a unit quaternion (w, x, y, z), as the classic suite's mat2euler."""
    w, x, y, z = quat
    m00 = 1.0 - 2.0 * (y * y + z * z)
    m01 = 2.0 * (x * y - w * z)
    m02 = 2.0 * (x * z + w * y)
    m10 = 2.0 * (x * y + w * z)
    m11 = 1.0 - 2.0 * (x * x + z * z)
    m12 = 2.0 * (y * z - w * x)
    m22 = 1.0 - 2.0 * (x * x + y * y)
    cy = math.hypot(m22, m12)
    if cy > _EPS4:
        return [-math.atan2(m12, m22), -math.atan2(-m02, cy), -math.atan2(m01, m00)]
    return [0.0, -math.atan2(-m02, cy), -math.atan2(-m10, m11)]
