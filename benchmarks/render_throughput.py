"""Render throughput on one core: camera images per second, ours against MuJoCo's bare mjr_render loop.

    python -m benchmarks.render_throughput [--tasks PickPlace-v2,Reach-v2,Bin-pick-v2,Drawer-open-v2]
        [--cameras front,wrist] [--size 84] [--seconds 0.4] [--rounds 5] [--cpu N] [--clock cpu]

Every thread of the process is pinned to one CPU (`--cpu`, default the first this process may use), and
software GL (Mesa's llvmpipe) is held to one thread (LP_NUM_THREADS=1 unless set) before the first GL
context is made; llvmpipe's threads, started later, inherit the pin. Per task, on one model and one state
(a seeded reset and 10 random steps), each renderer draws the cameras in turn at `--size` x `--size`:

- raw: MuJoCo's calls and nothing else: `mjv_updateScene`, `mjr_render`, then `mjr_readPixels` (render
  + read), or `mjr_finish` (render: glFinish, so the frame is drawn, not only queued);
- `mujoco.Renderer`: `update_scene(data, camera=name)` and `render()`, as its users write it;
- ours: `camera_obs.CameraImages.render`, the call that puts every camera's image in an observation, at
  image quality "full" (the raw loop's picture: the same pixels) and at "fast" (`rendering.IMAGE_QUALITIES`:
  no multisampling, no reflection; the default for observations and datasets);
- the env: `env.step` of `gym.make(task, cameras=..., image_size=...)` (fast) and of `gym.make(task)`,
  resets not timed.

A second table switches one thing off at a time in the raw render + read loop (shadows, reflections,
skybox: scene flags; 4x multisampling: a second context made with `offsamples` 0), then all four: where a
frame's time goes. Each round gives every subject one `--seconds` turn, after a first untimed round (llvmpipe compiles
its shaders then). Rates are medians over the rounds; a ratio is the median of the ratios within rounds.
With `--clock cpu` (the default) a rate counts this process's CPU time (every thread, all on the one CPU),
which other jobs on the machine disturb less than wall time (`--clock wall`), though they still slow a
core through shared caches. Run from the repository root.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import gymnasium as gym
import mujoco
import numpy as np

import fetch
from benchmarks._machine import machine_line
from fetch._gl import backend, context_class, make_renderer
from fetch.camera_obs import CameraImages, check_cameras
from fetch.errors import FetchError

TASKS = ("PickPlace-v2", "Reach-v2", "Bin-pick-v2", "Drawer-open-v2")

FLAG = mujoco.mjtRndFlag
WHERE = {
    "no shadows": ((FLAG.mjRND_SHADOW,), True),
    "no reflections": ((FLAG.mjRND_REFLECTION,), True),
    "no skybox": ((FLAG.mjRND_SKYBOX,), True),
    "no MSAA": ((), False),
    "no reflections, no MSAA (fast)": ((FLAG.mjRND_REFLECTION,), False),
    "none of these": ((FLAG.mjRND_SHADOW, FLAG.mjRND_REFLECTION, FLAG.mjRND_SKYBOX), False),
}
"""The second table's columns: name -> (the raw loop's scene flags switched off, multisampling on)."""


class Result(NamedTuple):
    """One task's medians: `rates` by subject [images/s or steps/s], `ours_over_raw` (ours / raw render + read),
    `fast_over_full` (ours at image quality fast / at full), `render_share` (the cameras' share of a step's
    time), `same_pixels` (raw, mujoco.Renderer and ours drew the same images), `gl` (the GL renderer's name)."""

    rates: dict[str, float]
    ours_over_raw: float
    fast_over_full: float
    render_share: float
    same_pixels: bool
    gl: str


def _nothing() -> None:
    pass


class Subject(NamedTuple):
    """One thing measured: `unit` does one timed piece of work and returns the images (or steps) it made;
    `enter` runs untimed before each turn, `between` untimed before each unit."""

    unit: Callable[[], int]
    enter: Callable[[], None] = _nothing
    between: Callable[[], None] = _nothing


def pin(cpu: int) -> None:
    """Pin every thread of this process to `cpu`; threads started later inherit it."""
    for tid in os.listdir("/proc/self/task"):
        os.sched_setaffinity(int(tid), {cpu})


def threads_pinned(cpu: int) -> tuple[int, bool]:
    """This process's thread count, and whether every one of them may run on `cpu` alone."""
    tids = os.listdir("/proc/self/task")
    return len(tids), all(os.sched_getaffinity(int(tid)) == {cpu} for tid in tids)


def mjr_context(model: mujoco.MjModel, multisample: bool = True) -> mujoco.MjrContext:
    """A MjrContext on the current GL context, as mujoco.Renderer makes it; without multisampling when asked."""
    samples = int(model.vis.quality.offsamples)
    model.vis.quality.offsamples = samples if multisample else 0  # read when the context is made
    try:
        return mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
    finally:
        model.vis.quality.offsamples = samples


class Raw:
    """MuJoCo's own render loop: a MjvScene (with the render flags `off` switched off) drawn by `context`."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, context: mujoco.MjrContext,
                 cameras: Sequence[str], size: int, off: Sequence[int] = ()) -> None:
        self.model, self.data, self.context = model, data, context
        self.scene = mujoco.MjvScene(model, maxgeom=10000)  # mujoco.Renderer's default
        for flag in off:  # mjv_updateScene leaves a scene's flags as they are
            self.scene.flags[flag] = False
        self.option = mujoco.MjvOption()
        self.cameras = []
        for name in cameras:
            camera = mujoco.MjvCamera()
            camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
            camera.fixedcamid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name)
            self.cameras.append(camera)
        self.rect = mujoco.MjrRect(0, 0, size, size)
        self.rgb = np.empty((size, size, 3), np.uint8)
        self._turn = 0

    def enter(self) -> None:
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self.context)

    def draw(self, camera: int, read: bool = True) -> None:
        """Camera number `camera`'s image, into `rgb` (bottom row first) when `read`."""
        mujoco.mjv_updateScene(self.model, self.data, self.option, None, self.cameras[camera],
                               mujoco.mjtCatBit.mjCAT_ALL, self.scene)
        mujoco.mjr_render(self.rect, self.scene, self.context)
        if read:
            mujoco.mjr_readPixels(self.rgb, None, self.rect, self.context)
        else:
            mujoco.mjr_finish()

    def frame(self, read: bool = True) -> int:
        """One image, of each camera in turn: 1."""
        self.draw(self._turn, read)
        self._turn = (self._turn + 1) % len(self.cameras)
        return 1


def random_actions(env: Any, n: int, seed: int) -> np.ndarray:
    """(n, action size) actions, uniform in [-1, 1]."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n, *np.shape(env.action_space.low)))


class Stepper:
    """An env stepped with pre-drawn uniform random actions; reset, untimed, when an episode ends."""

    def __init__(self, env: gym.Env, seed: int = 0) -> None:
        self.env = env
        env.reset(seed=seed)
        self.actions = random_actions(env, 1000, seed)
        self.i, self.done = 0, False

    def between(self) -> None:
        if self.done:
            self.env.reset()
            self.done = False

    def unit(self) -> int:
        _, _, terminated, truncated, _ = self.env.step(self.actions[self.i % len(self.actions)])
        self.i += 1
        self.done = terminated or truncated
        return 1


def turn(subject: Subject, seconds: float, clock: Callable[[], float]) -> float:
    """Images (or steps) per second of `clock` over one turn of about `seconds` of wall time."""
    subject.enter()
    count, spent, end = 0, 0.0, time.perf_counter() + seconds
    while time.perf_counter() < end or count == 0:
        subject.between()
        start = clock()
        count += subject.unit()
        spent += clock() - start
    return count / spent


def gl_name() -> str:
    """The current GL context's renderer and version strings."""
    # PyOpenGL picks its platform (EGL, OSMesa, GLX) when first imported: after MuJoCo's backend set it.
    from OpenGL import GL

    return f"{GL.glGetString(GL.GL_RENDERER).decode()}, {GL.glGetString(GL.GL_VERSION).decode()}"


def measure(task: str, cameras: tuple[str, ...], size: int, seconds: float, rounds: int,
            clock: Callable[[], float], cpu: int) -> Result:
    """One task: every subject in turn, `rounds` times after an untimed round."""
    env: Any = gym.make(task).unwrapped
    model, data = env.model, env.data
    cameras = check_cameras(model, cameras, size)
    env.reset(seed=0)
    for action in random_actions(env, 10, seed=0):
        env.step(action)
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), size)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), size)

    gl = context_class()(size, size)
    gl.make_current()
    gl_renderer = gl_name()
    contexts = {True: mjr_context(model), False: mjr_context(model, multisample=False)}
    raw = Raw(model, data, contexts[True], cameras, size)
    renderer = make_renderer(model, size, size)  # mujoco.Renderer on the GL backend ours uses
    ours = CameraImages(model, cameras, size, hide_goal=False, quality="full")
    fast = CameraImages(model, cameras, size, hide_goal=False, quality="fast")
    with_cameras = Stepper(gym.make(task, cameras=cameras, image_size=size))
    without = Stepper(gym.make(task))
    same = same_pixels(raw, renderer, ours, gl)
    # Again: Mesa's shader-cache thread, started with the first GL context, sets an affinity of its own.
    pin(cpu)

    def entering(loop: Raw) -> Callable[[], None]:
        def enter() -> None:
            gl.make_current()
            loop.enter()
        return enter

    def by_renderer() -> int:
        for name in cameras:
            renderer.update_scene(data, camera=name)
            renderer.render()
        return len(cameras)

    subjects = {
        "raw render": Subject(lambda: raw.frame(read=False), entering(raw)),
        "raw render+read": Subject(raw.frame, entering(raw)),
        "mujoco.Renderer": Subject(by_renderer),
        "ours": Subject(lambda: len(ours.render(data))),
        "ours, fast": Subject(lambda: len(fast.render(data))),
        "env step, cameras": Subject(with_cameras.unit, between=with_cameras.between),
        "env step": Subject(without.unit, between=without.between),
    }
    for name, (off, multisample) in WHERE.items():
        loop = Raw(model, data, contexts[multisample], cameras, size, off)
        subjects[name] = Subject(loop.frame, entering(loop))
    rates: dict[str, list[float]] = {name: [] for name in subjects}
    for r in range(rounds + 1):
        for name, subject in subjects.items():
            rate = turn(subject, seconds, clock)
            if r:
                rates[name].append(rate)

    ours.close()
    fast.close()
    renderer.close()
    gl.make_current()
    for context in contexts.values():
        context.free()
    gl.free()
    for each in (with_cameras.env, without.env, env):
        each.close()
    return Result(rates={name: statistics.median(values) for name, values in rates.items()},
                  ours_over_raw=statistics.median(o / w for o, w in zip(rates["ours"], rates["raw render+read"],
                                                                        strict=True)),
                  fast_over_full=statistics.median(f / o for f, o in zip(rates["ours, fast"], rates["ours"],
                                                                         strict=True)),
                  render_share=statistics.median(1 - c / p for c, p in zip(rates["env step, cameras"],
                                                                           rates["env step"], strict=True)),
                  same_pixels=same, gl=gl_renderer)


def same_pixels(raw: Raw, renderer: Any, ours: CameraImages, gl: Any) -> bool:
    """Whether raw, mujoco.Renderer and ours draw the same image of every camera: the same work."""
    images = ours.render(raw.data)  # makes ours's GL context
    same = True
    for i, (name, key) in enumerate(zip(ours.cameras, ours.keys, strict=True)):
        gl.make_current()
        raw.enter()
        raw.draw(i)
        renderer.update_scene(raw.data, camera=name)
        upright = raw.rgb[::-1]
        same = same and np.array_equal(upright, images[key]) and np.array_equal(upright, renderer.render())
    return same


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default=",".join(TASKS), help="comma-separated env ids")
    parser.add_argument("--cameras", default="front,wrist")
    parser.add_argument("--size", type=int, default=84, help="image side [px]")
    parser.add_argument("--seconds", type=float, default=0.4, help="one subject's turn in a round [s, wall]")
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds, after one untimed")
    parser.add_argument("--cpu", type=int, default=min(os.sched_getaffinity(0)), help="the CPU to pin to")
    parser.add_argument("--clock", choices=("cpu", "wall"), default="cpu")
    args = parser.parse_args(argv)
    tasks = tuple(t for t in args.tasks.split(",") if t)
    unknown = [t for t in tasks if t not in fetch.ENV_IDS]
    if unknown:
        parser.error(f"unknown task {unknown[0]!r}; known: {', '.join(fetch.ENV_IDS)}")
    if args.seconds <= 0 or args.rounds < 1:
        parser.error(f"--seconds must be > 0 and --rounds >= 1, got {args.seconds:g} and {args.rounds}")
    if args.cpu not in os.sched_getaffinity(0):
        parser.error(f"--cpu {args.cpu} is not one this process may use: {sorted(os.sched_getaffinity(0))}")
    cameras = tuple(c for c in args.cameras.split(",") if c)

    # Before the first GL context: llvmpipe reads its thread count when made, and its threads inherit the pin.
    os.environ.setdefault("LP_NUM_THREADS", "1")
    pin(args.cpu)
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    load = os.getloadavg()[0]
    results = {}
    for task in tasks:
        try:
            results[task] = measure(task, cameras, args.size, args.seconds, args.rounds, clock, args.cpu)
        except FetchError as e:  # a camera the scene lacks, a size out of range
            parser.error(str(e))
        print(f"{task}: done", flush=True)
    threads, pinned = threads_pinned(args.cpu)

    print(f"\n{machine_line()}")
    print(f"GL: {backend()} ({next(iter(results.values())).gl}); LP_NUM_THREADS={os.environ['LP_NUM_THREADS']}; "
          f"{threads} threads, {'all' if pinned else 'NOT all'} pinned to CPU {args.cpu}; load average "
          f"{load:.2f} before, {os.getloadavg()[0]:.2f} after; rates per {args.clock} second, medians of "
          f"{args.rounds} rounds of {args.seconds:g} s")
    size = f"{args.size} x {args.size}"
    print(f"\n{', '.join(cameras)} at {size}: images/s (fps) on one core, env steps/s")
    print("| task | raw mjr_render fps | raw render+read fps | mujoco.Renderer fps | ours fps | ours/raw "
          "| ours fast fps | fast/full | env steps/s, cameras (fast) | env steps/s, none | cameras' share of a step "
          "| same pixels |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for task, r in results.items():
        rate = r.rates
        print(f"| {task} | {rate['raw render']:,.0f} | {rate['raw render+read']:,.0f} "
              f"| {rate['mujoco.Renderer']:,.0f} | {rate['ours']:,.0f} | {r.ours_over_raw:.2f} "
              f"| {rate['ours, fast']:,.0f} | {r.fast_over_full:.1f} "
              f"| {rate['env step, cameras']:,.1f} | {rate['env step']:,.0f} | {r.render_share:.0%} "
              f"| {'yes' if r.same_pixels else 'NO'} |")
    print(f"\nWhere a raw frame's time goes: raw render+read fps at {size}, one thing off")
    print(f"| task | all on | {' | '.join(WHERE)} |")
    print(f"|---|{'---:|' * (len(WHERE) + 1)}")
    for task, r in results.items():
        cells = " | ".join(f"{r.rates[name]:,.0f}" for name in WHERE)
        print(f"| {task} | {r.rates['raw render+read']:,.0f} | {cells} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
