"""How well a person can steer in the collection window: what its picture shows, measured from the picture.

    python -m benchmarks.window_depth [--envs PickPlace-v2,Bin-pick-v2,Drawer-open-v2] [--states 300]
    python -m benchmarks.window_depth --candidates 40    # other places for the operator's camera, and the goal

First, what the window's frame costs to render (640 x 480, PickPlace-v2, the default view), with and
without multisampling, shadows and the sky: on a software renderer this decides the frames a person
sees per second. Then two measures, each per task and per way of showing the scene; the states are the
hand placed at random within 12 cm of the task's key object (1-15 cm above whatever is below it), from
seeds the estimator never saw.

1. **Seen**: the share of the fingers' and of the key object's pixels that are not hidden (by the arm, the
   robot, furniture), per camera: what a view shows of the contact a person steers towards.
2. **Height from the picture**: a stand-in operator that knows only the rendered frame. It finds the fingers
   (a perfect detector: the segmentation render), and in the window with its aid also the orange spot under
   the fingertips (by colour, in the RGB frame). From those pixel positions it learns the fingertips' height
   over the surface below (a quadratic least-squares fit on 200 states) and is scored on the others: the
   error of its estimate, and, steering down from 15 cm at 1 cm a step until it reads <= 1 cm, how often
   it stops 0.2-2 cm over the surface and how often it has touched it (closer than 2 mm) by then.

The ways of showing: `old` is the window before issue 40 (the front camera on the env's own scene, no
shadows, no aid); `view` is the new default camera without the aid (the estimator cannot use shadows, so
this isolates the camera); `window` is the new window (default camera, shadows, drop line and spot).
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import mujoco
import numpy as np

from benchmarks._machine import machine_line
from fetch.teleop.scenery import Scenery

SIZE = (320, 240)
KEY = {"object0": "object0", "block": "block", "lid": "lid", "drawer": "handle"}
"""The body whose geoms are the task's key object (for the drawers: only its handle's geoms)."""
STEP = 0.2
"""The descent's action: 0.2 x 5 cm = 1 cm a step."""
TOUCH = 0.002
"""[m] fingertips closer than this to the surface have touched it (the descent's last step overshot)."""


def key_geoms(model: mujoco.MjModel) -> np.ndarray:
    for body, part in KEY.items():
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body) >= 0:
            bid = model.body(body).id
            return np.array([g for g in range(model.ngeom) if model.geom_bodyid[g] == bid
                             and (part == body or part in model.geom(g).name)])
    raise SystemExit(f"no key object in {model}")


class Views:
    """Renders one env's state the three ways, RGB and segmentation."""

    def __init__(self, env: gym.Env) -> None:
        self.env = env.unwrapped
        self.scenery = Scenery(env)
        width, height = SIZE
        self.plain = mujoco.Renderer(self.env.model, height, width)
        self.dressed = mujoco.Renderer(self.scenery.model, height, width)
        for renderer in (self.plain, self.dressed):
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        m = self.scenery.model
        self.fingers = np.array([g for g in range(m.ngeom) if "finger" in m.body(m.geom_bodyid[g]).name])
        self.key = key_geoms(m)
        self.goal = np.array([m.geom("goal").id])

    def sync(self) -> None:
        self.scenery.sync(self.env.data)

    def frame(self, way: str, camera: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(RGB, geom id per pixel, -1 where none) of the current state, shown `way`."""
        renderer = self.plain if way == "old" else self.dressed
        data = self.env.data if way == "old" else self.scenery.data
        camera = camera or ("front" if way == "old" else self.env.task.view)
        renderer.update_scene(data, camera=camera)
        if way == "window":
            self.scenery.mark(renderer.scene)
        rgb = renderer.render().copy()
        renderer.enable_segmentation_rendering()
        renderer.update_scene(data, camera=camera)
        seg = renderer.render()
        renderer.disable_segmentation_rendering()
        ids = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
        return rgb, ids

    def unhidden(self, camera: str, geoms: np.ndarray) -> tuple[int, int]:
        """(pixels of `geoms` seen, pixels they would cover with nothing in front) from `camera`."""
        r, data = self.dressed, self.scenery.data
        r.enable_segmentation_rendering()
        r.update_scene(data, camera=camera)
        seen = np.isin(self._ids(r.render()), geoms).sum()
        r.update_scene(data, camera=camera)
        for i in range(r.scene.ngeom):  # everything else out of the picture: the geoms asked about alone
            geom = r.scene.geoms[i]
            if not (geom.objtype == mujoco.mjtObj.mjOBJ_GEOM and geom.objid in geoms):
                geom.pos[:] = (1e3, 1e3, 1e3)
        alone = np.isin(self._ids(r.render()), geoms).sum()
        r.disable_segmentation_rendering()
        return int(seen), int(alone)

    def hidden_by(self, camera: str, geoms: np.ndarray, by: np.ndarray) -> float:
        """The share of the pixels `geoms` would cover with nothing in front that `by` hides, from `camera`
        (1 when they are out of the picture)."""
        r, data = self.dressed, self.scenery.data
        r.enable_segmentation_rendering()
        r.update_scene(data, camera=camera)
        ids = self._ids(r.render())
        r.update_scene(data, camera=camera)
        for i in range(r.scene.ngeom):
            geom = r.scene.geoms[i]
            if not (geom.objtype == mujoco.mjtObj.mjOBJ_GEOM and geom.objid in geoms):
                geom.pos[:] = (1e3, 1e3, 1e3)
        alone = np.isin(self._ids(r.render()), geoms)
        r.disable_segmentation_rendering()
        return float(np.isin(ids[alone], by).mean()) if alone.any() else 1.0

    @staticmethod
    def _ids(seg: np.ndarray) -> np.ndarray:
        return np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)


def features(views: Views, way: str) -> np.ndarray | None:
    """What the stand-in reads from one frame: the fingers' pixel centroid and lowest pixel, and (window)
    the spot's centroid; None when the fingers are out of sight."""
    rgb, ids = views.frame(way)
    rows, cols = np.nonzero(np.isin(ids, views.fingers))
    if len(rows) < 3:
        return None
    found = [cols.mean(), rows.mean(), rows.max()]
    if way == "window":
        r, g, b = (rgb[..., i].astype(int) for i in range(3))
        spot = (r > 200) & (g > 90) & (g < 190) & (b < 80)
        sr, sc = np.nonzero(spot)
        found += [sc.mean(), sr.mean(), 1.0] if len(sr) >= 2 else [cols.mean(), rows.max(), 0.0]
    return np.array(found) / SIZE[1]


def design(x: np.ndarray) -> np.ndarray:
    """Quadratic features: 1, x, and the products of x's entries."""
    n = x.shape[1]
    quad = [x[:, i] * x[:, j] for i in range(n) for j in range(i, n)]
    return np.column_stack([np.ones(len(x)), x, *quad])


def place(env: gym.Env, views: Views, rng: np.random.Generator, seed: int, height: float) -> bool:
    """Reset with `seed` and bring the fingertips `height` [m] over the surface below a point near the key
    object; False if the hand did not get there (within 3 mm)."""
    base = env.unwrapped
    env.reset(seed=seed)
    m, d = base.model, base.data
    key = d.geom_xpos[views.key].mean(axis=0)
    xy = key[:2] + rng.uniform(-0.12, 0.12, 2)
    grip = m.site("robot0:grip").id
    for target_z in (0.75, None):
        if target_z is None:
            views.sync()
            if views.scenery.below is None:
                return False
            target_z = views.scenery.below[2] + height + views.scenery.fingertips
        for _ in range(40):
            move = (np.r_[xy, target_z] - d.site_xpos[grip]) / 0.05
            env.step(np.r_[np.clip(move, -1, 1), 1.0])
    views.sync()
    return views.scenery.height is not None and abs(views.scenery.height - height) < 0.003


def measure(env_id: str, states: int, seed: int) -> dict[str, dict[str, float]]:
    env = gym.make(env_id, max_episode_steps=10_000)
    views = Views(env)
    rng = np.random.default_rng(seed)
    ways = ("old", "view", "window")
    rows: dict[str, list[np.ndarray]] = {w: [] for w in ways}
    heights: list[float] = []
    seen = {c: np.zeros(4) for c in views.scenery.cameras}
    for i in range(states):
        if not place(env, views, rng, seed * 100_000 + i, float(rng.uniform(0.01, 0.15))):
            continue
        found = {w: features(views, w) for w in ways}
        if any(f is None for f in found.values()):
            continue
        for w in ways:
            rows[w].append(found[w])  # type: ignore[arg-type]
        heights.append(float(views.scenery.height))  # type: ignore[arg-type]
        if i % 3 == 0:
            for camera in seen:
                seen[camera] += [*views.unhidden(camera, views.fingers), *views.unhidden(camera, views.key)]
    y = np.array(heights)
    train = np.arange(len(y)) < int(0.67 * len(y))
    out: dict[str, dict[str, float]] = {}
    fits = {}
    for w in ways:
        x = design(np.array(rows[w]))
        coef, *_ = np.linalg.lstsq(x[train], y[train], rcond=None)
        fits[w] = coef
        error = x[~train] @ coef - y[~train]
        out[w] = {"rmse_cm": 100 * float(np.sqrt(np.mean(error**2))),
                  "p90_cm": 100 * float(np.percentile(np.abs(error), 90)), "test": int((~train).sum())}
    for w in ways:
        out[w].update(descend(env, views, rng, w, fits[w], trials=max(states // 6, 10), seed=seed + 7))
    out["seen"] = {c: (v[0] / max(v[1], 1), v[2] / max(v[3], 1)) for c, v in seen.items()}  # type: ignore[misc]
    env.close()
    return out


def descend(env: gym.Env, views: Views, rng: np.random.Generator, way: str, coef: np.ndarray, trials: int,
            seed: int) -> dict[str, float]:
    """From 15 cm, down 1 cm a step until the estimate reads <= 1 cm: where the fingertips stop."""
    stops = []
    for t in range(trials):
        if not place(env, views, rng, seed * 100_000 + t, 0.15):
            continue
        for _ in range(25):
            f = features(views, way)
            if f is not None and float((design(f[None]) @ coef)[0]) <= 0.01:
                break
            env.step(np.array([0.0, 0.0, -STEP, 1.0]))
            views.sync()
        stops.append(views.scenery.height if views.scenery.height is not None else -1.0)
    s = np.array(stops)
    return {"stopped_0_2cm": float(np.mean((s >= TOUCH) & (s <= 0.02))), "touched": float(np.mean(s < TOUCH)),
            "trials": len(s)}


def frame_costs(frames: int = 20) -> list[tuple[int, bool, bool, float]]:
    """[ms] per 640 x 480 frame of the window's scene, by (multisampling, shadows, sky)."""
    env = gym.make("PickPlace-v2")
    env.reset(seed=0)
    scenery = Scenery(env)
    scenery.sync(env.unwrapped.data)
    rows = []
    for samples in (4, 0):
        scenery.model.vis.quality.offsamples = samples
        renderer = mujoco.Renderer(scenery.model, 480, 640)
        for shadows in (False, True):
            for sky in (False, True):
                renderer.update_scene(scenery.data, camera=env.unwrapped.task.view)
                scenery.mark(renderer.scene)
                flags = renderer.scene.flags
                flags[mujoco.mjtRndFlag.mjRND_SHADOW], flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = shadows, sky
                flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
                renderer.render()
                start = time.perf_counter()
                for _ in range(frames):
                    renderer.render()
                rows.append((samples, shadows, sky, 1e3 * (time.perf_counter() - start) / frames))
        renderer.close()
    env.close()
    return rows


CANDIDATES = {
    "higher": ((0.9, 1.55, 1.65), (1.3, 0.75, 0.42)),
    "further forward": ((1.15, 1.65, 1.4), (1.3, 0.75, 0.42)),
    "beside, high": ((1.35, 1.7, 1.3), (1.3, 0.75, 0.42)),
    "further back, high": ((0.75, 1.45, 1.7), (1.3, 0.75, 0.42)),
    "before": ((0.9, 1.6, 1.35), (1.3, 0.75, 0.42)),
}
"""Other places for the `operator` camera, (position, target) [m], that `--candidates` compares with it."""


def candidates(env_ids: list[str], states: int) -> None:
    """The share of the fingers, the key object and the goal marker seen from each of `CANDIDATES` and the
    window's viewpoints."""
    from fetch.teleop import scenery

    scenery.VIEWPOINTS.update(CANDIDATES)  # this process only: every Scenery made now has them as cameras
    names = list(scenery.VIEWPOINTS)
    print("| task | " + " | ".join(names) + " |\n|---|" + "---|" * len(names))
    for env_id in env_ids:
        env = gym.make(env_id, max_episode_steps=10_000)
        views = Views(env)
        rng = np.random.default_rng(5)
        seen = {c: np.zeros(6) for c in names}
        for i in range(states):
            if place(env, views, rng, 900_000 + i, float(rng.uniform(0.01, 0.15))):
                for c in names:
                    seen[c] += [*views.unhidden(c, views.fingers), *views.unhidden(c, views.key),
                                *views.unhidden(c, views.goal)]
        print(f"| {env_id} (fingers / key object / goal seen) | "
              + " | ".join(f"{100 * v[0] / v[1]:.0f} / {100 * v[2] / v[3]:.0f} / {100 * v[4] / max(v[5], 1):.0f} %"
                           for v in seen.values()) + " |")
        env.close()
    print(f"\n| task (hand anywhere over the table, {states} states): goal over half hidden by the arm | "
          + " | ".join(names) + " |\n|---|" + "---|" * len(names))
    for env_id in env_ids:
        env = gym.make(env_id, max_episode_steps=10_000)
        views = Views(env)
        m = views.scenery.model
        arm = np.array([g for g in range(m.ngeom) if m.body(m.geom_bodyid[g]).name.startswith("robot0:")
                        and not any(part in m.body(m.geom_bodyid[g]).name for part in ("gripper", "finger"))])
        rng = np.random.default_rng(6)
        hidden = dict.fromkeys(names, 0)
        for i in range(states):
            anywhere(env, views, rng, 800_000 + i)
            for c in names:
                hidden[c] += views.hidden_by(c, views.goal, arm) > 0.5
        print(f"| {env_id} | " + " | ".join(f"{100 * n / states:.1f} %" for n in hidden.values()) + " |")
        env.close()


def anywhere(env: gym.Env, views: Views, rng: np.random.Generator, seed: int) -> None:
    """Reset with `seed` and move the hand to a random point over the table, 5-25 cm up (where a person
    steering it may be)."""
    base = env.unwrapped
    env.reset(seed=seed)
    grip = base.model.site("robot0:grip").id
    target = np.array([rng.uniform(1.05, 1.55), rng.uniform(0.4, 1.1), rng.uniform(0.45, 0.65)])
    for _ in range(30):
        env.step(np.r_[np.clip((target - base.data.site_xpos[grip]) / 0.05, -1, 1), 1.0])
    views.sync()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", default="PickPlace-v2,Bin-pick-v2,Drawer-open-v2")
    parser.add_argument("--states", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--candidates", type=int, default=0, metavar="STATES",
                        help="instead: compare other places for the operator's camera over this many states")
    args = parser.parse_args()
    if args.candidates:
        candidates(args.envs.split(","), args.candidates)
        return
    start = time.time()
    print(machine_line())
    print(f"{args.states} states per task, seed "
          f"{args.seed}, frames {SIZE[0]}x{SIZE[1]}\n")
    print(f"| multisampling | shadows | sky | ms per frame (MUJOCO_GL={os.environ.get('MUJOCO_GL', '(unset)')}) |"
          "\n|---|---|---|---|")
    for samples, shadows, sky, ms in frame_costs():
        print(f"| {samples} | {'on' if shadows else 'off'} | {'on' if sky else 'off'} | {ms:.1f} |")
    print()
    results = {env_id: measure(env_id, args.states, args.seed) for env_id in args.envs.split(",")}
    print("| task | shown | height error, RMSE [cm] | p90 [cm] | descents stopped 0.2-2 cm over | touched first | "
          "test states / descents |\n|---|---|---|---|---|---|---|")
    for env_id, r in results.items():
        for w in ("old", "view", "window"):
            v = r[w]
            print(f"| {env_id} | {w} | {v['rmse_cm']:.2f} | {v['p90_cm']:.2f} | {100 * v['stopped_0_2cm']:.0f} % | "
                  f"{100 * v['touched']:.0f} % | {v['test']} / {v['trials']:.0f} |")
    cameras = list(next(iter(results.values()))["seen"])
    print("\n| task | " + " | ".join(cameras) + " |\n|---|" + "---|" * len(cameras))
    for env_id, r in results.items():
        seen = r["seen"]
        print(f"| {env_id} (fingers / key object seen) | "
              + " | ".join(f"{100 * seen[c][0]:.0f} / {100 * seen[c][1]:.0f} %" for c in cameras) + " |")
    print(f"\n{time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
