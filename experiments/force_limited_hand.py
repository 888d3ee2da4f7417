"""Issue 20's lid: what a hand that pushes with a bounded force would give, tried on a copy of the model.

The seed tasks' hand follows its mocap target through a weld, which pushes as hard as it takes: under
random full-scale actions the fingers press the lid 37-48 mm into the box and the table (`benchmarks/bench_abuse.py`).
Here the weld is replaced, in a copy of the compiled model, by six site actuators on `gripper_link`
with their reference site on the mocap body (a PD towards the target pose, force- and torque-limited),
with the arm's gravity compensated; the action rule is unchanged (the target is put at the hand's pose
plus 0.05 m * a). Per variant: how far the hand moves in each of 8 full-scale +x steps from the start
(the weld: 31-32 mm), how far it still goes in the 10 steps after the command stops, how far the hand
tilts, and the worst contact penetration and launch under `--steps` random full-scale steps (as
bench_abuse.py makes and counts them), with the lid's contacts as shipped (MuJoCo's defaults) or the
room's stiff ones. A trial, not a product: the experts are not run.

    .venv/bin/python -m experiments.force_limited_hand --env Box-open-v2 --steps 2000   # ~1 min
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import mujoco
import numpy as np

import fetch  # noqa: F401  (registers the ids)
from benchmarks._machine import machine_line
from benchmarks.bench_abuse import measure
from fetch.scene import ROOM_SOLIMP, ROOM_SOLREF, _delete
from fetch.timing import N_SUBSTEPS

VARIANTS = ((3000, 300, 100), (10000, 600, 150), (10000, 600, 300), (30000, 1200, 300))
"""(kp [N/m], kv [N s/m], force limit [N]) of the translational PD; the rotational one is 300 N m/rad,
30 N m s/rad, 60 N m throughout."""


class Hand:
    """The task's model with the weld replaced by the force-limited PD; steps as the env's action rule."""

    def __init__(self, env_id: str, kp: float, kv: float, force: float, stiff_lid: bool) -> None:
        self.env = gym.make(env_id)
        base = self.env.unwrapped
        spec = base._compiled.spec.copy()  # type: ignore[attr-defined]
        _delete(spec, next(e for e in spec.equalities if int(e.type) == int(mujoco.mjtEq.mjEQ_WELD)))
        spec.body("robot0:mocap").add_site(name="hand_target")
        spec.body("robot0:gripper_link").add_site(name="hand_origin")
        for body in spec.bodies:
            if body.name.startswith("robot0:") and body.name != "robot0:mocap":
                body.gravcomp = 1.0
        for axis in range(6):
            act = spec.add_actuator(name=f"hand{axis}", trntype=mujoco.mjtTrn.mjTRN_SITE, target="hand_origin",
                                    refsite="hand_target")
            gear = [0.0] * 6
            gear[axis] = 1.0
            act.gear = gear
            k, c, limit = (kp, kv, force) if axis < 3 else (300.0, 30.0, 60.0)
            act.gaintype, act.biastype = mujoco.mjtGain.mjGAIN_FIXED, mujoco.mjtBias.mjBIAS_AFFINE
            act.gainprm[0] = 0.0
            act.biasprm[0:3] = [0.0, -k, -c]
            act.forcelimited, act.forcerange = True, [-limit, limit]
        self.model = m = spec.compile()
        self.data = mujoco.MjData(m)
        if stiff_lid:
            lid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "lid")
            geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == lid]
            m.geom_solref[geoms], m.geom_solimp[geoms] = ROOM_SOLREF, ROOM_SOLIMP
        self.hand = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "robot0:gripper_link")
        self.grip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "robot0:grip")
        self.mocap = int(m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "robot0:mocap")])
        self.fingers = [(a, int(m.jnt_qposadr[m.actuator_trnid[a, 0]])) for a in range(m.nu)
                        if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)]
        self.quat = np.zeros(4)

    def reset(self, seed: int) -> None:
        self.env.reset(seed=seed)
        src, d = self.env.unwrapped.data, self.data  # type: ignore[attr-defined]
        d.qpos[:], d.qvel[:], d.mocap_pos[:], d.mocap_quat[:] = src.qpos, src.qvel, src.mocap_pos, src.mocap_quat
        d.ctrl[:], d.time = 0.0, 0.0
        mujoco.mj_forward(self.model, d)
        self.quat = d.xquat[self.hand].copy()

    def step(self, action: np.ndarray) -> None:
        d, a = self.data, np.clip(np.asarray(action, np.float64), -1.0, 1.0)
        d.mocap_pos[self.mocap] = d.xpos[self.hand] + 0.05 * a[:3]
        d.mocap_quat[self.mocap] = self.quat
        for act, adr in self.fingers:
            d.ctrl[act] = d.qpos[adr] + a[3]
        mujoco.mj_step(self.model, d, nstep=N_SUBSTEPS)


def tracking(hand: Hand) -> tuple[np.ndarray, float, float]:
    """([mm] the hand's x move in each of 8 full-scale +x steps, [mm] how far it goes in 10 steps
    after, [deg] its tilt then)."""
    hand.reset(0)
    d = hand.data
    xs = [float(d.site_xpos[hand.grip][0])]
    for _ in range(8):
        hand.step(np.array([1.0, 0.0, 0.0, -1.0]))
        xs.append(float(d.site_xpos[hand.grip][0]))
    stopped = d.site_xpos[hand.grip].copy()
    for _ in range(10):
        hand.step(np.zeros(4))
    after = float(np.linalg.norm(d.site_xpos[hand.grip] - stopped))
    tilt = 2.0 * np.degrees(np.arccos(min(1.0, abs(float(np.dot(d.xquat[hand.hand], hand.quat))))))
    return np.diff(xs) * 1000.0, after * 1000.0, tilt


def abuse(hand: Hand, steps: int, seed: int = 0) -> tuple[float, str, float]:
    """([mm] the worst penetration under random full-scale steps, between what, [m/s] the fastest
    launch), made and counted by bench_abuse.py's `measure`."""
    worst = measure(hand.model, hand.data, hand.reset, hand.step, steps, seed)
    return float(worst["depth"]) * 1000.0, str(worst["depth_where"]), float(worst["launch"])  # type: ignore[arg-type]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Box-open-v2", choices=["Box-open-v2", "Box-close-v2"])
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args()
    print(machine_line())
    print(f"{args.env}, {args.steps} random full-scale steps\n")
    print("| kp [N/m] | kv [N s/m] | force limit [N] | lid contacts | +x move per step [mm] | after stopping [mm] "
          "| tilt [deg] | worst penetration [mm] | where | fastest launch [m/s] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for kp, kv, force in VARIANTS:
        for stiff in (False, True):
            hand = Hand(args.env, kp, kv, force, stiff)
            moves, after, tilt = tracking(hand)
            depth, where, launch = abuse(hand, args.steps)
            print(f"| {kp} | {kv} | {force} | {'stiff' if stiff else 'default'} | "
                  f"{' '.join(f'{v:.0f}' for v in moves)} | {after:.0f} | {tilt:.1f} | {depth:.1f} | {where} | "
                  f"{launch:.2f} |",
                  flush=True)


if __name__ == "__main__":
    main()
