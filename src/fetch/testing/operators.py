"""Stand-in operators with people's habits: a person's way of driving the pad, played through SDL's
virtual pad and the real `GamepadDevice`, closed-loop on what the scene shows.

Each `Style` is a set of habits (`docs/operators.md` describes them and what they do to the data):

- pace: how far the stick is pushed (`stick`), a reaction lag (`lag`: the operator acts on what it saw
  that many ticks ago) and an eager hand that overshoots and corrects (`gain` > 1 with the lag);
- pauses: before pressing X at the grasp, hands off while the fingers close, a stop mid-carry, and
  looks around (no input at all) at random moments;
- a missed grasp: the first close comes too high, on nothing; the operator opens and grasps again;
- gripper habits: X pressed early (while the hand still descends), X held down for a while;
- approach paths: the expert's (over, then straight down) or from the side (down to the approach
  height first, then in sideways).

Every range is drawn per attempt, so no two demos of a style are alike. The decisions come from the
task's scripted expert (`fetch.experts`), which reads only the observation, as a person reads the
scene; the habits are what the operator does with them. The tasks with a grasp (PickPlace, the bins
and boxes) and the drawers use every habit; on the others (Push, Reach) the grasp habits have no
moment to fire and the rest apply.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np

from fetch.dataset.habits import SQUEEZE
from fetch.experts.base import Stage
from fetch.experts.motion import Drawer, Push
from fetch.experts.pick import PickAndPlace

if TYPE_CHECKING:
    from fetch.teleop.session import SessionSummary

Range = tuple[float, float]


@dataclasses.dataclass(frozen=True)
class Style:
    """One way of driving. Ranges (lo, hi) are drawn uniformly at each attempt; ticks are 40 ms."""

    name: str
    summary: str
    noise: float = 0.1
    """a shaky hand: Gaussian noise on the stick and triggers while they are pushed (hands off: none)."""
    stick: Range = (1.0, 1.0)
    """the farthest the stick is pushed, a fraction of full tilt (a person at half stick: 0.5)."""
    lag: Range = (0, 0)
    """[ticks] reaction lag: the operator acts on what the scene showed this long ago."""
    gain: Range = (0.5, 0.5)
    """how hard the operator steers towards where it wants the hand, as a fraction of the most a
    proportional loop with its lag takes without growing oscillations (`stable_gain`): 0.5 is the
    expert's own gain without a lag; towards 1 the hand overshoots and corrects, more so with a lag."""
    pause_before_grasp: Range = (0, 0)
    """[ticks] a stop at the grasp (or the drawer's hook, the push's start) before acting on it."""
    pause_after_grasp: Range = (0, 0)
    """[ticks] hands off after pressing X, waiting for the fingers (the drawer: after hooking)."""
    pause_mid_carry: Range = (0, 0)
    """[ticks] a stop a few ticks into the carry (the pull, the push)."""
    look_every: float = 0.0
    """[ticks] mean time between looks around (0: never); each a pause of `look_ticks`."""
    look_ticks: Range = (0, 0)
    miss_grasp: float = 0.0
    """the chance that the first grasp closes 3 cm too high, on nothing, then opens and grasps again."""
    early_close: Range = (0.0, 0.0)
    """[m] X is pressed while the hand is still this high above the grasp point."""
    hold_x: Range = (1, 1)
    """[ticks] how long X is held down each time it is pressed (1: a tap)."""
    side_approach: float = 0.0
    """the chance that the hand first goes down to the approach height and only then over (the side)."""


STANDIN = Style("standin", "the project's first stand-in: the expert's intent with a shaky hand (noise 0.1)")
STYLES: dict[str, Style] = {s.name: s for s in (
    STANDIN,
    Style("rests", "stops at the grasp, presses X, hands off 12-17 ticks while the fingers close",
          pause_before_grasp=(3, 6), pause_after_grasp=(12, 17)),
    Style("slow", "a person's pace: half stick, a 0.15 s reaction lag, overshoot and correction",
          noise=0.05, stick=(0.45, 0.55), lag=(3, 5), gain=(0.6, 0.85)),
    Style("pauses", "stops before and after the grasp and mid-carry, and looks around with no input",
          pause_before_grasp=(5, 12), pause_after_grasp=(8, 20), pause_mid_carry=(8, 20),
          look_every=40.0, look_ticks=(8, 20)),
    Style("regrasp", "misses the first grasp (closes too high), opens, comes down and grasps again",
          miss_grasp=1.0, pause_after_grasp=(3, 8)),
    Style("gripper", "presses X early, while still coming down, and holds it down for a while",
          early_close=(0.01, 0.02), hold_x=(4, 10)),
    Style("side", "goes down to the approach height first, then in from the side",
          side_approach=1.0, stick=(0.7, 0.9)),
    Style("person", "all of it at once, drawn anew each demo, as a real person drives",
          noise=0.05, stick=(0.4, 1.0), lag=(1, 4), gain=(0.4, 0.8), pause_before_grasp=(0, 10),
          pause_after_grasp=(5, 20),
          pause_mid_carry=(0, 15), look_every=60.0, look_ticks=(5, 20), miss_grasp=0.3, early_close=(0.0, 0.015),
          hold_x=(1, 8), side_approach=0.5),
)}
"""The styles by name: `STANDIN` (the project's first stand-in) and the habits people have."""


def stable_gain(lag: int) -> float:
    """The largest gain g of the loop e[t+1] = e[t] - g e[t - lag] that does not oscillate ever wider:
    2 sin(pi / (2 (2 lag + 1))); 2 without a lag, 0.35 with a lag of 4 ticks."""
    return 2.0 * math.sin(math.pi / (2 * (2 * lag + 1)))


def contact_stage(expert: Any) -> Stage | None:
    """The expert's stage in which it makes its key contact: the grasp, the hook, the push."""
    if isinstance(expert, PickAndPlace):
        return Stage.CLOSE
    if isinstance(expert, Drawer):
        return Stage.PULL
    if isinstance(expert, Push):
        return Stage.PUSH
    return None


def carry_stage(expert: Any) -> Stage | None:
    """The expert's stage that moves the object to its goal."""
    if isinstance(expert, PickAndPlace):
        return Stage.CARRY
    return contact_stage(expert)


SIDE_LAG = 4
"""[ticks] the longest reaction lag of a style: a side approach counts the hand as standing on something
only after this many ticks of going down and 6 more without moving."""


def contact_point(expert: Any, obs: Any) -> np.ndarray | None:
    """[m] where the grip site goes for the key contact, as the expert computes it (None: no such point)."""
    if isinstance(expert, PickAndPlace):
        return expert.part(obs, f"{expert.grasp.obj}_pos") + np.asarray(expert.grasp.grip_offset)
    if isinstance(expert, Drawer):
        return expert.part(obs, "handle_pos") + [expert.gap, 0.0, 0.0]
    return None


class Operator:
    """A stand-in for a person with a pad, of one `Style`: use it as a collection `Device`.

    The expert decides from the observation the operator saw `lag` ticks ago; the operator's habits
    shape what reaches the pad (stick, triggers, RB for precision, X for the gripper); the real
    `GamepadDevice` reads the pad back, so a demo made this way took the whole path a person's does.
    """

    name = "gamepad"
    OPEN_ABOVE = 0.005
    """X closes the fingers when the expert squeezes (its a[3] at or below generation's `SQUEEZE`)
    and opens them when it wants them this much wider than they are [m] (its finger servo's a[3]);
    between the two it leaves the gripper alone, as a person does."""
    MISS_HEIGHT = 0.03
    """[m] how high above the grasp point a missed grasp closes."""

    def __init__(self, pad: Any, device: Any, expert: Any, style: Style = STANDIN, seed: int = 0) -> None:
        self.pad, self.device, self.expert, self.style = pad, device, expert, style
        self.rng = np.random.default_rng(seed)
        self._held: dict[str, int] = {}  # buttons down -> ticks left (RB: until released)
        self._released: set[str] = set()
        self.reset_habits()

    def draw(self, r: Range, whole: bool = True) -> float:
        value = self.rng.uniform(r[0], r[1]) if r[1] > r[0] else r[0]
        return float(round(value)) if whole else float(value)

    def reset_habits(self) -> None:
        s = self.style
        self.stick = self.draw(s.stick, whole=False)
        self.lag = int(self.draw(s.lag))
        self.expert.gain = self.draw(s.gain, whole=False) * stable_gain(self.lag)
        self.miss = s.miss_grasp > 0 and self.rng.random() < s.miss_grasp
        self.early = self.draw(s.early_close, whole=False)
        self.side = s.side_approach > 0 and self.rng.random() < s.side_approach
        self.seen: deque[Any] = deque(maxlen=self.lag + 1)
        self.pause = 0
        self.stage = self.expert.stage
        self.carry_ticks = 0
        self.paused_carry = False
        self.grasps = 0
        self.missing = 0  # ticks left of a missed grasp's hands-off wait

    def reset(self) -> None:
        self.device.reset()
        self.expert.reset()
        self.reset_habits()

    def _press(self, button: str, ticks: int = 1) -> None:
        if button not in self._held:
            self.pad.press(button)
        self._held[button] = max(ticks, 1)

    def _release_due(self) -> None:
        """Release the buttons whose time is up; one released now is not pressed again this tick (the
        pad would show no edge, and a toggle would be lost)."""
        self._released = {b for b, left in self._held.items() if b != "rightshoulder" and left <= 1}
        for button in self._released:
            self.pad.release(button)
            del self._held[button]
        for button in self._held:
            if button != "rightshoulder":
                self._held[button] -= 1

    def _hands_off(self) -> Any:
        self._side_heights: list[float] = []  # a hand at rest is not one standing on something
        self.pad.set_stick(0.0, 0.0)
        self.pad.set_triggers(0.0, 0.0)
        if "rightshoulder" in self._held:
            self.pad.release("rightshoulder")
            del self._held["rightshoulder"]

    def _gripper(self, want: float) -> None:
        """X when the gripper should change: a tap or a hold (a toggle fires once per press)."""
        closed = self.device.mapper.gripper_closed
        if "x" in self._held or "x" in self._released:
            return
        if (want > self.OPEN_ABOVE) if closed else (want <= SQUEEZE):
            self._press("x", int(self.draw(self.style.hold_x)))
            if not closed:
                self.grasps += 1
                if self.expert.stage is Stage.CLOSE:
                    self.pause = max(self.pause, int(self.draw(self.style.pause_after_grasp)))

    def _stick(self, move: np.ndarray) -> None:
        if self.style.noise:
            move = move + self.rng.normal(0.0, self.style.noise, 3)
        move = np.clip(move, -1.0, 1.0)
        largest = float(np.abs(move).max())
        if largest > self.stick:
            move = move * (self.stick / largest)
        scale = self.device.config.precision_scale
        fine = float(np.abs(move).max()) < scale
        if fine != ("rightshoulder" in self._held):
            if fine:
                self._press("rightshoulder")
            else:
                self.pad.release("rightshoulder")
                del self._held["rightshoulder"]
        x, y, z = np.clip(move / scale, -1.0, 1.0) if fine else move
        self.pad.set_stick(float(x), float(-y))  # SDL's stick y points down
        self.pad.set_triggers(max(0.0, -float(z)), max(0.0, float(z)))

    def poll(self, obs: Any) -> Any:
        self._release_due()
        self.seen.append(obs)
        if self.pause > 0:  # hands off: a wait, a look around
            self.pause -= 1
            self._hands_off()
            return self.device.poll(obs)
        s = self.style
        if s.look_every and self.rng.random() < 1.0 / s.look_every:
            self.pause = int(self.draw(s.look_ticks))
            self._hands_off()
            return self.device.poll(obs)
        view = self.seen[0]  # what the operator saw `lag` ticks ago
        if self.missing:
            self.missing -= 1
            self._hands_off()
            return self.device.poll(obs)
        side = self._side_approach(view)
        if side is not None:
            self._stick(side)
            return self.device.poll(obs)
        action = np.asarray(self.expert(view), dtype=np.float64)
        stage = self.expert.stage
        entered = stage is not self.stage
        self.stage = stage
        if entered and stage is contact_stage(self.expert):
            wait = int(self.draw(s.pause_before_grasp))
            if stage is not Stage.CLOSE:  # a hook or a push: no X to wait for, one stop at the contact
                wait += int(self.draw(s.pause_after_grasp))
            if wait:
                self.pause = wait - 1
                self._hands_off()
                return self.device.poll(obs)
        if stage is carry_stage(self.expert):
            self.carry_ticks += 1
            if self.carry_ticks == 5 and not self.paused_carry:
                self.paused_carry = True
                self.pause = int(self.draw(s.pause_mid_carry))
        want = float(action[3])
        point = contact_point(self.expert, view)
        if stage is Stage.DESCEND and point is not None and self.grasps == 0:
            above = float(self.expert.part(view, "grip_pos")[2] - point[2])
            if self.miss and above <= self.MISS_HEIGHT:
                self.miss = False  # closes on nothing; waits for the fingers, then lets the expert see it
                self._press("x", int(self.draw(s.hold_x)))
                self.grasps += 1
                self.missing = 8
                self._hands_off()
                return self.device.poll(obs)
            if self.early and above <= self.early:
                want = -1.0
        self._stick(action[:3])
        self._gripper(want)
        return self.device.poll(obs)

    def _side_approach(self, view: Any) -> np.ndarray | None:
        """The move of a side approach (down to the approach height, then over), or None once there."""
        if not self.side:
            return None
        point = contact_point(self.expert, view)
        if point is None:
            self.side = False
            return None
        grip = self.expert.part(view, "grip_pos")
        height = point[2] + 0.06
        self._side_heights = [*getattr(self, "_side_heights", [])[-(SIDE_LAG + 5):], float(grip[2])]
        recent = self._side_heights[-6:]
        blocked = len(self._side_heights) > SIDE_LAG + 5 and np.ptp(recent) < 0.002
        if abs(grip[2] - height) < 0.01 or blocked:  # there, or standing on something (a cabinet's top): go over
            self.side = False
            self._side_heights = []
            return None
        return np.array([0.0, 0.0, np.clip(self.expert.gain * (height - grip[2]) / 0.05, -1.0, 1.0)])

    def close(self) -> None:
        for button in self._held:
            self.pad.release(button)
        self._held.clear()
        self.device.close()


def drive(pad: Any, env_id: str, style: str, out: Any, demos: int, seed: int = 0,
          starts: str = "all") -> SessionSummary:
    """A collection session of `demos` demos of `env_id` by a stand-in of `style` (a name in `STYLES`), through
    the virtual pad `pad`, the real `GamepadDevice` and the real collector, into the dataset `out` (from `starts`,
    as `collect --starts`): its summary, however many it saved."""
    from fetch.experts import make_expert
    from fetch.teleop.gamepad import GamepadDevice
    from fetch.teleop.session import CollectConfig, Session, make_env

    config = CollectConfig(env_id=env_id, out=str(out), episodes=demos, device="gamepad", render="none",
                           control_hz=0, max_steps=400, seed=seed, starts=starts)
    env = make_env(config)
    operator = Operator(pad, GamepadDevice(), make_expert(env), STYLES[style], seed=seed)
    return Session(config, operator, env=env, log=lambda _: None).run()


def record(pad: Any, env_id: str, style: str, out: Any, demos: int, seed: int = 0) -> Any:
    """`out`, holding `demos` successful demos of `env_id` by a stand-in of `style` (`drive`); an error where
    the session saved fewer."""
    summary = drive(pad, env_id, style, out, demos, seed)
    if summary.saved != demos:
        raise RuntimeError(f"{style} on {env_id}: {summary.describe()}")
    return out
