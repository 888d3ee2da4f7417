"""Many worlds of one compiled model: their states as rows, stepped on C threads where mujoco can.

`mujoco.batch.Batch` (mujoco >= 4.0) loads each world's mjSTATE_INTEGRATION row into an MjData,
runs it on a pool of C threads without the GIL and saves the row back; it is bit-identical to one
MjData per world at any thread count. Older mujoco has no such call: `mujoco.rollout` takes the
mocap and controls per substep but returns no warm start (`qacc_warmstart`), so the next control step's
solver would start elsewhere and differ in the last bits at once, and `mj_step` holds the GIL there.
`SerialWorlds` then runs the same calls one world after another: same results, one core.
"""

from __future__ import annotations

import abc
import copy
import importlib.util

import mujoco
import numpy as np

from fetch.robot import N_SUBSTEPS, present

STATE_SPEC = int(mujoco.mjtState.mjSTATE_INTEGRATION)
_NO_SENSORS = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
_FIELDS = {
    "qpos": mujoco.mjtState.mjSTATE_QPOS,
    "ctrl": mujoco.mjtState.mjSTATE_CTRL,
    "mocap_pos": mujoco.mjtState.mjSTATE_MOCAP_POS,
    "mocap_quat": mujoco.mjtState.mjSTATE_MOCAP_QUAT,
}

THREADED_SENSING_FROM = 4
"""From this many C threads on, the sensors are computed on them too (`Batch.forward` to stage VEL,
~4x the CPU of `present()`: it runs collision detection as well). Below, one `present()` per world
in Python (a few µs) takes less wall time."""


def has_batch() -> bool:
    """Whether this mujoco has `mujoco.batch` (4.0 on), the threaded path."""
    return importlib.util.find_spec("mujoco.batch") is not None


class StateLayout:
    """Where MjData fields sit in an mjSTATE_INTEGRATION row. A state lists its components in the
    order of their mjtState bits, so a component starts after the size of the bits below it."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.size = mujoco.mj_stateSize(model, STATE_SPEC)
        self._cols = {}
        for name, bit in _FIELDS.items():
            start = mujoco.mj_stateSize(model, STATE_SPEC & (int(bit) - 1))
            self._cols[name] = slice(start, start + mujoco.mj_stateSize(model, int(bit)))

    def view(self, rows: np.ndarray, name: str) -> np.ndarray:
        """Field `name` ("qpos", "ctrl", "mocap_pos", "mocap_quat") of state rows (n, size), as a
        (n, ...) view: mocap fields as (n, nmocap, 3 or 4)."""
        part = rows[:, self._cols[name]]
        if name == "mocap_pos":
            return part.reshape(rows.shape[0], -1, 3)
        if name == "mocap_quat":
            return part.reshape(rows.shape[0], -1, 4)
        return part


class Worlds(abc.ABC):
    """`nworld` worlds of one model. `state` (nworld, nstate) holds each world's mjSTATE_INTEGRATION
    row and is the truth: write a row's controls, mocap or joints there and the next call uses them.
    After `step` or `sense`, the rows of `hand_pos`/`hand_quat` [m, world] of the worlds of that call
    hold the pose of body `hand` that call computed, and after `sense` `sensordata` their sensors.
    `ids` are sorted world indices (None: every world)."""

    parallel: bool
    nthread: int
    state: np.ndarray
    hand_pos: np.ndarray
    hand_quat: np.ndarray
    sensordata: np.ndarray

    def __init__(self, model: mujoco.MjModel, nworld: int, hand: int) -> None:
        self._model = model
        # Sensors only feed the observation, so the substeps run with them off, as Robot.advance does.
        self._stepping = copy.copy(model)
        self._stepping.opt.disableflags |= _NO_SENSORS
        self._data = mujoco.MjData(model)
        self._hand = hand
        self.nworld = nworld
        self.hand_pos = np.zeros((nworld, 3))
        self.hand_quat = np.zeros((nworld, 4))
        self.sensordata = np.zeros((nworld, model.nsensordata))

    @abc.abstractmethod
    def step(self, ids: np.ndarray | None) -> None:
        """`N_SUBSTEPS` physics steps with sensors off; the hand's pose is then the one at the
        start of the last substep, as `mj_step` leaves it."""

    def sense(self, ids: np.ndarray | None) -> None:
        """Positions, velocities and sensors of the present state, world by world (`robot.present`)."""
        m, d, hand = self._model, self._data, self._hand
        for i in range(self.nworld) if ids is None else ids.tolist():
            mujoco.mj_setState(m, d, self.state[i], STATE_SPEC)
            present(m, d)
            self.hand_pos[i] = d.xpos[hand]
            self.hand_quat[i] = d.xquat[hand]
            self.sensordata[i] = d.sensordata

    def close(self) -> None:  # noqa: B027 (optional hook)
        """Release threads and buffers."""


class BatchWorlds(Worlds):
    """The worlds in a `mujoco.batch.Batch`, stepped on `nthread` C threads (0: every CPU)."""

    parallel = True

    def __init__(self, model: mujoco.MjModel, nworld: int, hand: int, nthread: int = 0) -> None:
        from mujoco import batch  # mujoco >= 4.0; has_batch() says whether it is there

        super().__init__(model, nworld, hand)
        self._batch = batch.Batch(self._stepping, nworld, nthread)
        self.nthread = int(self._batch.nthread)
        self.state = self._batch.state
        if self.state.shape != (nworld, mujoco.mj_stateSize(model, STATE_SPEC)):
            raise RuntimeError(f"mujoco.batch rows have shape {self.state.shape}; expected mjSTATE_INTEGRATION's")
        self.threaded_sensing = self.nthread >= THREADED_SENSING_FROM
        self._xpos, self._xquat = self._batch.bind("xpos"), self._batch.bind("xquat")
        if self.threaded_sensing:
            self._sensordata = self._batch.bind("sensordata")

    def step(self, ids: np.ndarray | None) -> None:
        if self.threaded_sensing:
            self._batch.set_models(self._stepping)
        self._batch.step(ids, nstep=N_SUBSTEPS)
        sel = slice(None) if ids is None else ids
        self.hand_pos[sel] = self._xpos[sel, self._hand]
        self.hand_quat[sel] = self._xquat[sel, self._hand]

    def sense(self, ids: np.ndarray | None) -> None:
        if not self.threaded_sensing:
            super().sense(ids)
            return
        # Stage VEL is mj_step1's work at the present state: positions (and collisions, which
        # present() skips), velocities and their sensors; it changes no state.
        self._batch.set_models(self._model)
        self._batch.forward(ids, stage=int(mujoco.mjtStage.mjSTAGE_VEL))
        sel = slice(None) if ids is None else ids
        self.hand_pos[sel] = self._xpos[sel, self._hand]
        self.hand_quat[sel] = self._xquat[sel, self._hand]
        self.sensordata[sel] = self._sensordata[sel]

    def close(self) -> None:
        self._batch.set_models(None)


class SerialWorlds(Worlds):
    """The same calls on one MjData, one world after another (mujoco without `mujoco.batch`)."""

    parallel = False
    nthread = 1

    def __init__(self, model: mujoco.MjModel, nworld: int, hand: int) -> None:
        super().__init__(model, nworld, hand)
        self.state = np.zeros((nworld, mujoco.mj_stateSize(model, STATE_SPEC)))

    def step(self, ids: np.ndarray | None) -> None:
        m, d, hand = self._stepping, self._data, self._hand
        for i in range(self.nworld) if ids is None else ids.tolist():
            mujoco.mj_setState(m, d, self.state[i], STATE_SPEC)
            mujoco.mj_step(m, d, nstep=N_SUBSTEPS)
            mujoco.mj_getState(m, d, self.state[i], STATE_SPEC)
            self.hand_pos[i] = d.xpos[hand]
            self.hand_quat[i] = d.xquat[hand]


def make_worlds(model: mujoco.MjModel, nworld: int, hand: int, nthread: int = 0) -> Worlds:
    """C threads where this mujoco has them (`mujoco.batch`), else one world after another."""
    if has_batch():
        return BatchWorlds(model, nworld, hand, nthread)
    return SerialWorlds(model, nworld, hand)
