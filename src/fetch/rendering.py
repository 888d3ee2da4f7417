"""Offscreen rendering (rgb and depth) and the passive MuJoCo viewer for render_mode="human"."""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from fetch._gl import backend, has_display, make_renderer
from fetch.errors import FetchError, UnknownNameError
from fetch.looks import Looks
from fetch.scene import GOAL_GROUP

CAMERAS = ("front", "side", "behind", "wrist")
"""The cameras this package adds to every scene, the ones to choose from (`scene.CAMERAS` places the first
three; `wrist` rides on the gripper). The robot model's own (head_camera_rgb, ...) still render when
named, but are not offered."""


MAX_IMAGE_SIZE = 2048
"""[px] the largest image or video side a tool renders (a 2048 x 2048 RGB frame is 12 MB)."""


def check_image_size(size: int, flag: str) -> None:
    """FetchError unless `size` [px] is a whole number from 1 to `MAX_IMAGE_SIZE`."""
    if not isinstance(size, int) or not 1 <= size <= MAX_IMAGE_SIZE:
        raise FetchError(f"{flag} must be a whole number of pixels from 1 to {MAX_IMAGE_SIZE}, got {size}")


def check_camera_list(cameras: Sequence[str], flag: str = "--cameras") -> None:
    """FetchError if a camera is named twice (each is recorded once, under its name); `flag` is the CLI
    flag or the keyword argument (`cameras=`, an env's) that named them."""
    twice = sorted({c for c in cameras if list(cameras).count(c) > 1})
    if twice:
        once = tuple(dict.fromkeys(cameras))
        example = f"{flag} {','.join(once)}" if flag.startswith("-") else f"{flag}={once}"
        raise FetchError(f"{flag} names {', '.join(twice)} more than once; list each camera once, e.g. {example}")


def camera_names(model: mujoco.MjModel) -> tuple[str, ...]:
    """The model's cameras, in order."""
    return tuple(model.camera(i).name for i in range(model.ncam))


def check_camera(model: mujoco.MjModel, camera: str) -> None:
    """UnknownNameError naming our cameras (`CAMERAS`) unless `camera` is one of the model's."""
    names = camera_names(model)
    if camera not in names:
        raise UnknownNameError("camera", camera, [c for c in CAMERAS if c in names] or names)


def _scene_option(hide_goal: bool) -> mujoco.MjvOption:
    option = mujoco.MjvOption()
    option.geomgroup[GOAL_GROUP] = 0 if hide_goal else 1
    return option


IMAGE_QUALITIES = ("fast", "full")
"""How a camera image for a policy or a dataset is drawn. "full" is the scene as the viewer shows it: 4x
multisampling (the scenes' `offsamples`) and the room floor's reflection. "fast" draws one sample per pixel
and no reflection: 2-4x the frames per core of a software renderer (docs/rendering.md), the same shapes,
lights and shadows, harder edges. Datasets recorded before there was a choice hold "full" images."""
DEFAULT_IMAGE_QUALITY = "fast"
"""What `cameras=` observations, `collect --cameras`, `generate --cameras` and `render-obs` draw unless told."""
QUALITY_HELP = ("how the images are drawn: fast (the default): one sample per pixel and no floor reflection, "
                "2-4x the frames per core of a software renderer; full: as the viewer shows the scene (4x "
                "multisampling, reflections)")


def check_image_quality(quality: str, flag: str) -> str:
    """`quality` when it is one of `IMAGE_QUALITIES`, else a one-line FetchError naming them."""
    if quality not in IMAGE_QUALITIES:
        raise FetchError(f"{flag} {quality!r}: choose one of {', '.join(IMAGE_QUALITIES)}")
    return quality


class OffscreenRenderer:
    """Renders the env's data from a named camera into an array, without a display, at `quality`
    (`IMAGE_QUALITIES`; "full": as the viewer shows the scene)."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, quality: str = "full") -> None:
        check_image_quality(quality, "image quality")
        # The offscreen buffer must hold the image; this model is the env's own copy.
        model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
        model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
        samples = int(model.vis.quality.offsamples)
        if quality == "fast":  # read when the GL context is made: this renderer's alone
            model.vis.quality.offsamples = 0
        try:
            self._renderer = make_renderer(model, height=height, width=width)
        except FetchError:
            raise
        except Exception as exc:  # the GL backend's own error types vary
            raise FetchError(
                f"offscreen rendering failed with the {backend()} OpenGL backend "
                f"(MUJOCO_GL={os.environ.get('MUJOCO_GL', '(unset)')}): {exc}. Set MUJOCO_GL=egl "
                "(libEGL, from libegl1) or osmesa (apt-get install libosmesa6)") from exc
        finally:
            model.vis.quality.offsamples = samples
        self._options = {hide: _scene_option(hide) for hide in (False, True)}
        self._depth = False
        self._camera_ids: dict[str, int] = {}  # each camera's id, looked up once (a `Looks` paints per camera)
        self._off = (mujoco.mjtRndFlag.mjRND_REFLECTION,) if quality == "fast" else ()

    def render(self, data: mujoco.MjData, camera: str, depth: bool = False,
               hide_goal: bool = False, looks: Looks | None = None) -> np.ndarray:
        """An (H, W, 3) uint8 image, or with depth=True an (H, W) float32 depth map [m]; drawn with `looks`
        (`fetch.looks`) where given, else as modelled."""
        if depth != self._depth:
            if depth:
                self._renderer.enable_depth_rendering()
            else:
                self._renderer.disable_depth_rendering()
            self._depth = depth
        self._renderer.update_scene(data, camera=camera, scene_option=self._options[hide_goal])
        for flag in self._off:
            self._renderer.scene.flags[flag] = False
        if looks is not None:
            if camera not in self._camera_ids:
                self._camera_ids[camera] = mujoco.mj_name2id(data.model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
            looks.paint(self._renderer.scene, self._camera_ids[camera])
        return self._renderer.render()

    def close(self) -> None:
        self._renderer.close()


class HumanViewer:
    """MuJoCo's passive viewer on a named camera, paced to real time."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, camera: str, hide_goal: bool) -> None:
        if not has_display():
            raise FetchError('render_mode="human" needs a display (none is set: DISPLAY is empty); '
                             'use render_mode="rgb_array", or run under Xvfb (xvfb-run python ...)')
        import mujoco.viewer

        self._handle: Any = mujoco.viewer.launch_passive(model, data, show_left_ui=False,
                                                         show_right_ui=False)
        self._handle.cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._handle.cam.fixedcamid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        self._handle.opt.geomgroup[GOAL_GROUP] = 0 if hide_goal else 1
        self._last = time.perf_counter()

    def sync(self, period: float) -> None:
        """Show the current data; wait out what is left of `period` [s] since the last call."""
        self._handle.sync()
        wait = period - (time.perf_counter() - self._last)
        if wait > 0:
            time.sleep(wait)
        self._last = time.perf_counter()

    def close(self) -> None:
        self._handle.close()
