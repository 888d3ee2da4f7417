"""What the collection window shows beyond the env's own scene: depth a person can see.

A person steering in 3-D from one picture needs to judge how high the fingers are over what is below
them. The window therefore draws its own copy of the task's model with a sky, a large checkered floor
(perspective), a key light straight overhead that casts shadows (the fingers' shadow falls right below
them), the person's viewpoints (`VIEWPOINTS`), and, every frame, a drop line from the hand to the
surface below it ending in a spot (`Scenery.mark`). The env's model is untouched: physics,
observations, recorded data and the model hash stay what they are. The copy takes the env's positions
each tick (qpos and the mocap bodies: everything that places anything) and computes where things are.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from fetch.rendering import CAMERAS, GOAL_GROUP, camera_names
from fetch.scene import look_at

VIEWPOINTS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "operator": ((0.9, 1.8, 1.2), (1.3, 0.8, 0.32)),
    "left": ((1.05, 1.55, 0.8), (1.2, 0.75, 0.45)),
}
"""[m] the window's own cameras, (position, what they look at): `operator`, beyond the table's near edge
on the robot's left and above it (the arm reaches away from it, so it hides neither the hand nor the
table, and from this low the wrist rarely hides a goal beyond the hand; a view from behind the robot
looks through the robot's head and arm), and `left`, lower, from the same side, level with a drawer's
handle so the hook behind it shows. A task names its default (`fetch.tasks.Task.view`);
`docs/window.md` has the measurements."""

SKY = ((0.55, 0.70, 0.88), (0.92, 0.94, 0.96))
"""The sky's gradient, top to horizon (RGB)."""
FLOOR = ((0.62, 0.60, 0.56), (0.45, 0.44, 0.41))
"""The floor's two checker colours (RGB); squares of `FLOOR_SQUARE`."""
FLOOR_SQUARE = 0.25
"""[m] the floor's checker squares: perspective the eye reads distance from."""
FLOOR_SIZE = 4.0
"""[m] the floor's half-width: it reaches the horizon of every viewpoint."""
SHADOW_MAP = 2048
"""[texels] the key light's shadow map: its edges are blocky below this, and 4096 costs a software renderer
(llvmpipe) twice the frame."""
SAMPLES = 0
"""Multisampling of the window's offscreen buffer (the task's models ask for 4): off, it halves a software
renderer's frame (640 x 480 with shadows: 58 -> 31 ms), at the price of jagged edges (docs/window.md)."""
DROP_COLOUR = (1.0, 0.55, 0.0, 1.0)
"""The drop line's and spot's colour: orange, seen against the table, floor and every object."""
DROP_WIDTH = 0.0015
"""[m] the drop line's radius."""
SPOT_RADIUS = 0.01
"""[m] the spot's radius, on the surface below the hand."""
HIDDEN_GROUPS = (GOAL_GROUP, 4)
"""Geom groups the drop line passes through: the goal marker, and the mocap body's crosshair."""


def decorate(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """A copy of `spec` with the window's sky, floor, shadow-casting key light and viewpoints."""
    spec = spec.copy()
    for texture in spec.textures:
        if texture.type == mujoco.mjtTexture.mjTEXTURE_SKYBOX:
            texture.builtin = mujoco.mjtBuiltin.mjBUILTIN_GRADIENT
            texture.rgb1, texture.rgb2 = SKY
    if not any(t.type == mujoco.mjtTexture.mjTEXTURE_SKYBOX for t in spec.textures):
        spec.add_texture(name="window_sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                         builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, rgb1=SKY[0], rgb2=SKY[1],
                         width=256, height=1536)
    spec.add_texture(name="window_floor", type=mujoco.mjtTexture.mjTEXTURE_2D,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=FLOOR[0], rgb2=FLOOR[1],
                     width=256, height=256)
    floor = spec.add_material(name="window_floor", texuniform=True,
                              texrepeat=[1.0 / (2 * FLOOR_SQUARE)] * 2, reflectance=0.0)
    floor.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "window_floor"
    planes = [g for g in spec.worldbody.geoms if g.type == mujoco.mjtGeom.mjGEOM_PLANE]
    if not planes:
        planes = [spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, contype=0, conaffinity=0)]
    for plane in planes:
        plane.size = [FLOOR_SIZE, FLOOR_SIZE, 0.05]
        plane.material = "window_floor"
    # The key light: the first directional light shining (nearly) straight down, or one added. Only it casts
    # shadows (each casting light is a shadow pass).
    key = next((i for i, light in enumerate(spec.lights) if light.dir[2] < -0.9 and _directional(light)), None)
    if key is None:
        key = len(spec.lights)
        _make_directional(spec.worldbody.add_light(name="window_key", pos=[1.3, 0.75, 3.0], dir=[0.0, 0.0, -1.0],
                                                   diffuse=[0.5, 0.5, 0.5]))
    for i, light in enumerate(spec.lights):
        light.castshadow = i == key
    spec.visual.quality.shadowsize = SHADOW_MAP
    spec.visual.quality.offsamples = SAMPLES
    for name, (pos, target) in VIEWPOINTS.items():
        spec.worldbody.add_camera(name=name, pos=pos, fovy=45.0, quat=look_at(pos, target))
    return spec


def _directional(light: Any) -> bool:
    """Whether a light is directional (mujoco >= 3.4 says it by `type`, 3.3 by `directional`)."""
    if hasattr(light, "type"):
        return bool(light.type == mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    return bool(light.directional)


def _make_directional(light: Any) -> None:
    if hasattr(light, "type"):
        light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    else:
        light.directional = True


class Scenery:
    """The window's copy of an env's scene (`decorate`), kept where the env is by `sync`.

    `cameras`: what the window can show, the person's viewpoints first; `height` [m]: the fingertips'
    height over the surface below them at the last `sync` (None when nothing is below).
    """

    def __init__(self, env: Any) -> None:
        base = env.unwrapped
        self.model = decorate(base.scene_spec()).compile()
        self.data = mujoco.MjData(self.model)
        names = camera_names(self.model)
        self.cameras = [*VIEWPOINTS, *(c for c in CAMERAS if c in names)]
        self._grip = self.model.site("robot0:grip").id
        self._robot = np.array([self.model.body(b).name.startswith("robot0:") for b in range(self.model.nbody)])
        self._groups = np.array([0 if g in HIDDEN_GROUPS else 1 for g in range(mujoco.mjNGROUP)], np.uint8)
        self._geom_id = np.zeros(1, np.int32)
        self._place(base.data)
        self.fingertips = self._fingertip_drop()
        """[m] how far the fingertips reach below the grip site."""
        self.below: np.ndarray | None = None
        """[m, world] the point on the surface below the hand, at the last `sync`."""
        self.height: float | None = None

    def _fingertip_drop(self) -> float:
        """[m] how far the fingertips reach below the grip site, from where they are now (the hand points down
        throughout): the lowest corner of the finger geoms' bounding boxes."""
        m, d = self.model, self.data
        lowest = d.site_xpos[self._grip][2]
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        for g in range(m.ngeom):
            if "finger" in m.body(m.geom_bodyid[g]).name:
                centre, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
                corners = (centre + signs * half) @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g]
                lowest = min(lowest, float(corners[:, 2].min()))
        return float(d.site_xpos[self._grip][2] - lowest)

    def sync(self, data: mujoco.MjData) -> None:
        """Put everything where it is in the env's `data`, and find the surface below the hand."""
        self._place(data)
        self._drop()

    def _place(self, data: mujoco.MjData) -> None:
        d = self.data
        d.qpos[:] = data.qpos
        d.mocap_pos[:] = data.mocap_pos
        d.mocap_quat[:] = data.mocap_quat
        mujoco.mj_kinematics(self.model, d)
        mujoco.mj_camlight(self.model, d)

    def _drop(self) -> None:
        """Cast a ray straight down from the grip site, through the robot's own geoms, to the first other
        surface (an object, furniture, the table, the floor)."""
        point = self.data.site_xpos[self._grip].copy()
        down = np.array([0.0, 0.0, -1.0])
        travelled = 0.0
        self.below, self.height = None, None
        for _ in range(8):  # the fingers, the palm: a few robot geoms at most lie on the way
            distance = mujoco.mj_ray(self.model, self.data, point, down, self._groups, 1, -1, self._geom_id)
            if distance < 0:
                return
            travelled += distance
            point = point + down * distance
            if not self._robot[self.model.geom_bodyid[self._geom_id[0]]]:
                self.below = point
                self.height = travelled - self.fingertips
                return
            point = point + down * 1e-4

    def mark(self, scene: mujoco.MjvScene) -> None:
        """Add the drop line and the spot to `scene` (after `mjv_updateScene`), if there is room."""
        if self.below is None or scene.ngeom + 2 > scene.maxgeom:
            return
        top = self.data.site_xpos[self._grip]
        spot = self.below + np.array([0.0, 0.0, 0.0008])
        rgba = np.array(DROP_COLOUR, np.float32)
        line = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(line, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), np.zeros(9), rgba)
        mujoco.mjv_connector(line, mujoco.mjtGeom.mjGEOM_CAPSULE, DROP_WIDTH, top, spot)
        scene.ngeom += 1
        disc = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(disc, mujoco.mjtGeom.mjGEOM_CYLINDER, np.array([SPOT_RADIUS, SPOT_RADIUS, 0.0005]),
                            spot, np.eye(3).flatten(), rgba)
        scene.ngeom += 1
        for geom in (line, disc):
            geom.category = mujoco.mjtCatBit.mjCAT_DECOR
            geom.emission = 0.6

    def yaw(self, camera: str) -> float:
        """[rad] `camera_yaw` of one of `cameras`, at the last `sync`."""
        return camera_yaw(self.model, self.data, camera)


def camera_yaw(model: mujoco.MjModel, data: mujoco.MjData, camera: str) -> float:
    """[rad] The rotation from the fixed stick mapping (`--frame world`: stick up = world +y) to the camera's:
    stick up then moves the hand away from the viewer, along the camera's view on the table."""
    cam = model.camera(camera).id
    forward = -data.cam_xmat[cam].reshape(3, 3)[:, 2]  # a camera looks along its -z axis
    if math.hypot(forward[0], forward[1]) < 1e-6:  # looking straight down: use its image up
        forward = data.cam_xmat[cam].reshape(3, 3)[:, 1]
    return math.atan2(-forward[0], forward[1])
