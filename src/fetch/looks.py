"""How a scene looks in camera images: as modelled ("plain"), or drawn anew each episode ("random").

A pixel policy trained on one table colour, one light and one camera mount can fail when any of them
changes; domain randomisation (Tobin et al., 2017) trains it on many. `looks="random"` (an env option,
`generate --looks`, `eval --looks`) draws, at each reset, the colours of everything that is not the
robot, the lights' strength and direction, and each camera's mount (a small shift and turn). The draw
changes what is drawn, never the model or the physics: a `Looks` repaints the `MjvScene` after
`mjv_updateScene` and before `mjr_render`, so the same seeds give the same episodes, states, rewards
and replays as with "plain", and any thread's renderer can draw any world's looks.

The looks of an episode are a function of its reset seed alone (`for_seed`), drawn from a child of the
seed's `SeedSequence` (`Generator.spawn`): the task's own random stream is not consumed, and a dataset's
images can be drawn again from its recorded seeds (`render-obs`, `generate`'s workers).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from fetch.errors import FetchError
from fetch.scene import GOAL_GROUP

LOOKS = ("plain", "random")
"""The choices of the `looks` option: as modelled, or drawn per episode (`Looks`)."""

COLOUR_GAIN = (0.7, 1.3)
"""Range of the factor on each of a thing's red, green and blue (drawn per thing and channel)."""
COLOUR_SHIFT = 0.1
"""The most added to or taken from each channel of a thing's colour (0-1 scale)."""
LIGHT_GAIN = (0.6, 1.3)
"""Range of the factor on every light's diffuse strength (one draw an episode)."""
AMBIENT_GAIN = (0.5, 1.5)
"""Range of the factor on every light's ambient strength (one draw an episode)."""
LIGHT_TILT = 0.2
"""Standard deviation of what is added to x and y of each light's unit direction (the headlight's aside)."""
CAMERA_SHIFT = 0.01
"""[m] the most each camera moves along each world axis."""
CAMERA_TURN = np.radians(1.5)
"""[rad] the most each camera turns, about an axis drawn at random."""
ROBOT_PREFIX = "robot0:"
"""Bodies whose names start so are the robot: it keeps its colours (the lights still vary on it)."""


def check_looks(looks: str, flag: str = "looks") -> str:
    """`looks` when it is one of `LOOKS`, else a one-line FetchError naming them."""
    if looks not in LOOKS:
        raise FetchError(f"{flag} {looks!r}: choose one of {', '.join(LOOKS)}")
    return looks


def seed_generator(seed: int) -> np.random.Generator:
    """The generator the looks of an episode reset with `seed` are drawn from: the first child of the
    seed's `SeedSequence`, as `Generator.spawn` gives it from the env's freshly seeded `np_random`."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed).spawn(1)[0]))


def painted_things(model: mujoco.MjModel) -> dict[int, int]:
    """Model geom id -> the index of the thing whose colour it takes: one thing per material (a bin's walls
    share theirs) or per geom without one. The robot's geoms and the goal's marker are not among them."""
    things: dict[tuple[str, int], int] = {}
    out: dict[int, int] = {}
    for geom in range(model.ngeom):
        body = model.body(int(model.geom_bodyid[geom])).name
        if body.startswith(ROBOT_PREFIX) or int(model.geom_group[geom]) == GOAL_GROUP:
            continue
        material = int(model.geom_matid[geom])
        key = ("material", material) if material >= 0 else ("geom", geom)
        out[geom] = things.setdefault(key, len(things))
    return out


@dataclasses.dataclass(frozen=True)
class Looks:
    """One episode's looks. `paint(scene, camera)` applies them to a scene `mjv_updateScene` just made."""

    things: dict[int, int]
    """model geom id -> row of `gain` and `shift` (`painted_things`)."""
    gain: np.ndarray
    """(things, 3) factors on red, green and blue."""
    shift: np.ndarray
    """(things, 3) what is then added to them (the result clipped to 0-1)."""
    light_gain: float
    ambient_gain: float
    tilt: np.ndarray
    """(lights, 2) added to x and y of the model lights' directions, in the model's light order."""
    camera_shift: np.ndarray
    """(cameras, 3) [m] per model camera, world frame."""
    camera_turn: np.ndarray
    """(cameras, 3, 3) per model camera, the rotation of its view (world frame)."""
    _colours: dict[int, np.ndarray] = dataclasses.field(default_factory=dict, compare=False, repr=False)
    """model geom id -> its painted red, green and blue, worked out the first time it is drawn (a geom's
    colour as modelled does not change), so a frame costs a copy per geom, not the arithmetic."""

    @classmethod
    def draw(cls, model: mujoco.MjModel, rng: np.random.Generator) -> Looks:
        things = painted_things(model)
        n = max(things.values(), default=-1) + 1
        gain = rng.uniform(*COLOUR_GAIN, size=(n, 3))
        shift = rng.uniform(-COLOUR_SHIFT, COLOUR_SHIFT, size=(n, 3))
        light_gain, ambient_gain = rng.uniform(*LIGHT_GAIN), rng.uniform(*AMBIENT_GAIN)
        tilt = rng.normal(0.0, LIGHT_TILT, size=(model.nlight, 2))
        camera_shift = rng.uniform(-CAMERA_SHIFT, CAMERA_SHIFT, size=(model.ncam, 3))
        turns = np.empty((model.ncam, 3, 3))
        for camera in range(model.ncam):
            axis = rng.normal(size=3)
            quat = np.empty(4)
            mujoco.mju_axisAngle2Quat(quat, axis / np.linalg.norm(axis), rng.uniform(-CAMERA_TURN, CAMERA_TURN))
            matrix = np.empty(9)
            mujoco.mju_quat2Mat(matrix, quat)
            turns[camera] = matrix.reshape(3, 3)
        return cls(things, gain, shift, float(light_gain), float(ambient_gain), tilt, camera_shift, turns)

    @classmethod
    def for_seed(cls, model: mujoco.MjModel, seed: int) -> Looks:
        """The looks of the episode an env with looks="random" resets with `seed`."""
        return cls.draw(model, seed_generator(seed))

    def paint(self, scene: mujoco.MjvScene, camera: int) -> None:
        """Repaint `scene` (made by `mjv_updateScene` from model camera `camera`) with these looks: once per
        update, as the lights' strengths are scaled where they stand."""
        geom_type, things, colours = int(mujoco.mjtObj.mjOBJ_GEOM), self.things, self._colours
        geoms = scene.geoms
        for i in range(scene.ngeom):
            geom = geoms[i]
            if geom.objtype != geom_type or (thing := things.get(geom.objid)) is None:
                continue
            colour = colours.get(geom.objid)
            if colour is None:
                colour = colours[geom.objid] = np.clip(geom.rgba[:3] * self.gain[thing] + self.shift[thing], 0, 1)
            geom.rgba[:3] = colour
        lights, model_light = scene.lights, 0
        for i in range(scene.nlight):
            light = lights[i]
            light.diffuse[:] = light.diffuse * self.light_gain
            light.ambient[:] = light.ambient * self.ambient_gain
            if not light.headlight and model_light < len(self.tilt):
                direction = np.asarray(light.dir, np.float64).copy()
                direction[:2] += self.tilt[model_light]
                light.dir[:] = direction / max(float(np.linalg.norm(direction)), 1e-9)
                model_light += 1
        if 0 <= camera < len(self.camera_shift):
            turn = self.camera_turn[camera]
            for eye in scene.camera:  # the two eyes of a stereo pair, the same when mono
                eye.pos[:] = eye.pos + self.camera_shift[camera]
                eye.forward[:] = turn @ eye.forward
                eye.up[:] = turn @ eye.up
