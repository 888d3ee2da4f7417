"""The Slide expert: strike the puck onto a line through the goal, then strike it along that line.

It plans with the puck's physics (`fetch.experts.strikes`: glides bend onto an axis or a diagonal,
and a measured table of how far a strike sends the puck) and the closed fingers' geometry:

- A face of the closed fingers sends the puck along the face's normal (it rolls along the face) and
  their outer corner along the diagonal, whichever way the hand moves. So the puck goes along x,
  along y or along a diagonal, nothing else.
- Along x the face is the two fingertips side by side with a slot between them: a puck struck
  at the slot wedges into it and tips up, so an x strike uses one fingertip (`FINGER`); a corner
  strike has the puck's centre `CORNER` past the fingers' side. Both strike with the hand moving
  along x from rest 1 cm behind the puck.
- The plan: from where the puck will rest, a shot if the goal is on an axis or a diagonal from
  it; else a first strike that leaves the goal on one (along x then the diagonal, or along the
  diagonal then x; for goals mostly across, along y then the diagonal), whichever pair the strike
  table says fits; if neither does, along y then x or x then y where that fits. The next plan
  starts from where the puck will rest.
- 50 steps are short: the hand lines up for the next strike while the puck still glides, low
  (below the puck's top) whenever neither the hand's way nor the puck's crosses the other; and
  success is judged at the last step, not at rest, so a shot that would still be gliding then is
  struck harder, to be near the goal at `horizon` (`hurry`).
- With a `Twin` (what `make_expert` gives it), the expert first plays its plan out in its private
  copy of the task, which is exact while the episode gets the expert's own actions. If the plan
  ends more than `sure` from the goal, it plays first strikes along x, y and the diagonal towards
  the goal, to `FIRST_STRIKES` distances, each followed by its own plan, and strikes first the one
  that ends nearest (the table and its two-strike plans alone run short of time or of the arm's
  strength far out to the side).

docs/tasks.md ("Scripted experts") has what each part measured; experiments/slide_reach.py searches
what one or two strikes can reach.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping

import numpy as np

from fetch.experts.base import Expert, Stage
from fetch.experts.strikes import (
    DECELERATION,
    RADIUS,
    STRIKE_STEPS,
    glide,
    glide_time,
    is_diagonal,
    strike_reach,
    strike_size,
)
from fetch.experts.twin import Twin
from fetch.timing import CONTROL_DT

FRONT = 0.0144
"""[m] the closed fingers' front face, along x from the grip site."""
SIDES = (0.0152, -0.0166)
"""[m] the closed fingers' +y and -y side faces, along y from the grip site."""
MIDDLE = -0.001
"""[m] the middle of the fingers' side faces, along x from the grip site."""
FINGER = 0.012
"""[m] where the puck's centre is across the hand (y) from the grip site when one fingertip pushes
it along x: on the +y fingertip (0.8 to 15.2 mm), off the slot between the two and off its corner."""
CORNER = 0.0177
"""[m] ...and how far past the fingers' side it is when their corner pushes it along the diagonal: the
puck's radius over sqrt(2), so that the corner meets its rim at 45 degrees (on mujoco >= 4.0.1 the puck
goes 4-6 degrees short of the diagonal, the corner sliding along the rim; 8.8 mm, right for 4.0.0's edge
contacts, sends it 15-20 degrees short there)."""
BOX = (np.array([-0.0164, SIDES[1]]), np.array([FRONT, SIDES[0]]))
"""[m] the closed fingers' extent (xy) from the grip site: low, high corners."""

FIRST_STRIKES = np.arange(0.05, 0.65, 0.025)
"""[m] how far the first strikes that a twin plays out send the puck (72 plays, ~3 s, where the
plan falls short)."""


class Slide(Expert):
    """Plan -> line up -> push (a strike) -> watch, until the puck will rest on the goal."""

    arrived = 0.03
    """[m] no further push once the puck will rest this close to the goal..."""
    leave = 0.045
    """[m] ...until something moves it further than this (a correction risks more than it gains)."""
    on_line = 0.02
    """[m] the goal counts as on a diagonal (or an axis) from the puck within this across."""
    shortest = 0.04
    """[m] no strike aims to move the puck less than this."""
    gap = 0.010
    """[m] free space between the fingers and the puck where the hand comes down."""
    hover = 0.045
    """[m] how high above the puck's centre the hand crosses over it."""
    margin = 0.006
    """[m] the fingers pass the puck at least this far off when they stay low."""
    close = 0.01
    """[m] the hand counts as at the start of a strike within this..."""
    aligned = 0.0025
    """[m] ...and within this across the strike (the face or corner it strikes with is a few mm wide)."""
    at_rest = 0.05
    """[m/s] a puck slower than this counts as stopped."""
    still = 0.1
    """[m/s] a hand slower than this counts as stopped (a strike from a hand still moving across
    lands on another face)."""
    horizon = 50
    """[steps] the episode's length (Fetch*-v4's): success is judged at its last step."""
    integral = 0.3
    """[1] the fraction of its error the hand's target adds up each step (a stretched arm stalls short
    of a target a few mm away)."""

    sure = 0.04
    """[m] a plan that the twin plays out to end this close to the goal is struck without a search."""

    def __init__(self, layout: Mapping[str, slice], gain: float = 1.0, twin: Twin | None = None) -> None:
        self.twin = twin
        super().__init__(layout, gain)

    def reset(self) -> None:
        super().reset()
        self.first: tuple[np.ndarray, np.ndarray] | None = None  # a first strike chosen in the twin
        self.sent: np.ndarray | None = None  # the action returned last (the twin takes it too)
        self.line = np.array([1.0, 0.0])  # where the push sends the puck (unit, xy)
        self.motion = np.array([1.0, 0.0])  # where the hand moves during the push (unit, xy)
        self.offset = np.zeros(2)  # the puck's centre from the grip site at contact (xy)
        self.target = np.zeros(2)  # where the strike should leave the puck (xy)
        self.size_now = 0.0  # the strike's action size
        self.hold = np.zeros(3)
        self.bias = np.zeros(3)
        self.pushes = 0
        self.steps = 0  # steps taken this episode
        self.goal = np.zeros(2)

    def __call__(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        if self.twin is not None:
            if self.sent is None:
                self.twin.start(obs)
                if self.twin.in_step:
                    self.choose_first(obs)
            else:
                self.twin.follow(self.sent, obs)
        self.sent = super().__call__(obs)
        return self.sent

    def choose_first(self, obs: Mapping[str, np.ndarray]) -> None:
        """Play the plan out in the twin; if it falls short, the first strike that ends nearest."""
        assert self.twin is not None
        nearest = self.twin.play(self.rehearsal(), self.horizon)
        if nearest < self.sure:
            return
        puck, goal = self.part(obs, "object_pos")[:2], np.asarray(obs["desired_goal"])[:2]
        sx, sy = (float(np.sign(d) or 1.0) for d in goal - puck)
        best = None
        for line in (np.array([sx, 0.0]), np.array([0.0, sy]), np.array([sx, sy]) / np.sqrt(2.0)):
            for distance in FIRST_STRIKES:
                first = (line, puck + line * distance)
                ended = self.twin.play(self.rehearsal(first), self.horizon)
                if ended < nearest:
                    best, nearest = first, ended
        self.first = best

    def rehearsal(self, first: tuple[np.ndarray, np.ndarray] | None = None) -> Slide:
        """A copy of this expert, as it is now, without the twin, striking `first` first if given."""
        twin, self.twin = self.twin, None
        try:
            copied = copy.deepcopy(self)
        finally:
            self.twin = twin
        if first is not None:
            copied.first = first
        return copied

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        puck = self.part(obs, "object_pos")
        velocity = (self.part(obs, "object_velp") + self.part(obs, "grip_velp"))[:2] / CONTROL_DT
        goal = np.asarray(obs["desired_goal"])
        self.goal, self.steps = goal[:2].copy(), self.steps + 1
        rest = puck[:2] + glide(velocity)
        if self.stage is Stage.WATCH and self.timer < 2:
            return self.back_off(grip, puck)
        if self.stage in (Stage.START, Stage.WATCH, Stage.DONE) or self.stage is Stage.LINE_UP:
            self.plan(rest, goal, grip)
        if self.stage is Stage.DONE:
            return self.toward(grip, self.hold)
        if self.stage is Stage.LINE_UP:
            hand = float(np.linalg.norm(self.part(obs, "grip_velp")[:2])) / CONTROL_DT
            return self.line_up(grip, puck, rest, float(np.linalg.norm(velocity)), hand)
        return self.push(grip, puck, velocity)

    def plan(self, rest: np.ndarray, goal: np.ndarray, grip: np.ndarray) -> None:
        """Choose the next push from where the puck will come to rest."""
        error = goal[:2] - rest
        if np.linalg.norm(error) < (self.leave if self.stage is Stage.DONE else self.arrived):
            self.finish(grip, goal)
            return
        dx, dy = float(error[0]), float(error[1])
        sx, sy = float(np.sign(dx) or 1.0), float(np.sign(dy) or 1.0)
        diagonal = np.array([sx, sy]) / np.sqrt(2.0)
        if self.first is not None and self.pushes == 0:
            line, target = self.first
        elif abs(dy) < self.on_line:
            line, target = np.array([sx, 0.0]), goal[:2]
        elif abs(abs(dx) - abs(dy)) < self.on_line:
            line, target = diagonal, goal[:2]
        elif abs(dx) < self.on_line:
            line, target = np.array([0.0, sy]), goal[:2]
        else:
            line, target = self.two_strikes(rest, goal[:2])
            if float(np.linalg.norm(target - rest)) < self.shortest:
                # Too short a strike to be sure of (the hand barely reaches the puck): shoot along
                # the nearer line instead, missing by about that much.
                axis = np.array([sx, 0.0]) if abs(dx) > abs(dy) else np.array([0.0, sy])
                line = axis if abs(abs(dx) - abs(dy)) > min(abs(dx), abs(dy)) else diagonal
                target = goal[:2]
        changed = not np.allclose(line, self.line) or self.stage is not Stage.LINE_UP
        self.line, self.target = line, target
        self.motion, self.offset = self.contact(line)
        if changed:
            self.advance(Stage.LINE_UP)

    def two_strikes(self, rest: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The first of two strikes (its line and where it should leave the puck) that take the
        puck from `rest` to `goal` [m, xy]: an axis then the diagonal, or the diagonal then an
        axis; the pair the strike tables say fits best, then the one whose glides are shorter. If
        neither fits the arm's strength: also along y then x, or x then y."""
        dx, dy = goal - rest
        sx, sy = float(np.sign(dx) or 1.0), float(np.sign(dy) or 1.0)
        diagonal = np.array([sx, sy]) / np.sqrt(2.0)
        small = min(abs(dx), abs(dy))
        along_x, along_y = np.array([sx, 0.0]), np.array([0.0, sy])

        def plan(line: np.ndarray, target: np.ndarray, then: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
            """(line, target, shortfall [m]: how far either leg is beyond the strike table's reach,
            [s] how long the two glides take)."""
            first, second = float(np.linalg.norm(target - rest)), float(np.linalg.norm(goal - target))
            short = max(first - strike_reach(rest, line), second - strike_reach(target, then), 0.0)
            time = glide_time(first, is_diagonal(line)) + glide_time(second, is_diagonal(then), self.arrived)
            return line, target, short, time

        def rank(candidate: tuple[np.ndarray, np.ndarray, float, float]) -> tuple[float, float]:
            return candidate[2], candidate[3]

        if abs(dx) > abs(dy):
            # Along x onto the goal's diagonal, or along the diagonal onto the goal's y.
            plans = [plan(along_x, np.array([goal[0] - sx * small, rest[1]]), diagonal),
                     plan(diagonal, np.array([rest[0] + sx * small, goal[1]]), along_x)]
        else:
            # Along y onto the goal's diagonal, or along the diagonal onto the goal's x.
            plans = [plan(along_y, np.array([rest[0], goal[1] - sy * small]), diagonal),
                     plan(diagonal, np.array([goal[0], rest[1] + sy * small]), along_y)]
        best = min(plans, key=rank)
        if best[2] > 0.0:
            # Beyond the arm's strength (far out, or to the side): a strike across first may leave
            # an x strike it can make. Not otherwise: x strikes after y strikes stray more often.
            best = min([best, plan(along_y, np.array([rest[0], goal[1]]), along_x),
                        plan(along_x, np.array([goal[0], rest[1]]), along_y)], key=rank)
        return best[0], best[1]

    def contact(self, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How the hand strikes the puck along `line`: its motion and the puck's centre from the
        grip site at contact (xy)."""
        if line[0] == 0.0:  # a side face, the hand moving along y
            side = SIDES[0] if line[1] > 0 else SIDES[1]
            return line.copy(), np.array([MIDDLE, side + np.sign(line[1]) * RADIUS])
        motion = np.array([np.sign(line[0]), 0.0])
        if line[1] == 0.0:  # one fingertip's face
            across = FINGER
        else:  # a fingertip's outer corner, this far past its side
            across = SIDES[0] + CORNER if line[1] > 0 else SIDES[1] - CORNER
        return motion, np.array([np.sign(line[0]) * (FRONT + RADIUS), across])

    def finish(self, grip: np.ndarray, goal: np.ndarray) -> None:
        """No more pushes: hold still, clear above the puck."""
        if self.stage is not Stage.DONE:
            self.hold = np.array([*grip[:2], goal[2] + self.hover])
            self.advance(Stage.DONE)

    def start(self, puck: np.ndarray, gap: float) -> np.ndarray:
        """[m] where the grip site is when the fingers are `gap` behind the puck (xy)."""
        return puck[:2] - self.offset - self.motion * gap

    def line_up(self, grip: np.ndarray, puck: np.ndarray, rest: np.ndarray, speed: float,
                hand: float) -> np.ndarray:
        """To the start behind where the puck will rest, low if neither the hand's way there nor
        the puck's way to rest crosses the other, else over the puck; strike once it has stopped."""
        start = self.start(rest, self.gap)
        off = float(np.linalg.norm(grip[:2] - start))
        low = abs(grip[2] - puck[2]) < 0.007
        gliding = _clear(np.linspace(puck[:2], rest, 9), start[None], RADIUS + self.margin)
        across = float(np.linalg.norm((grip[:2] - start) - ((grip[:2] - start) @ self.motion) * self.motion))
        if low and off < self.close and across < self.aligned and speed < self.at_rest and hand < self.still:
            self.pushes += 1
            self.advance(Stage.PUSH)
            return self.toward(grip, np.array([*start, puck[2]]))
        if gliding and _clear(puck[None, :2], np.linspace(grip[:2], start, 9), RADIUS + self.margin):
            return self.toward(grip, np.array([*start, puck[2]]))
        high = puck[2] + self.hover
        if grip[2] < high - 0.02:
            return self.toward(grip, np.array([*grip[:2], high]))
        return self.toward(grip, np.array([*start, high]))

    def push(self, grip: np.ndarray, puck: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Strike: `STRIKE_STEPS` steps of one action along the motion, sized for the distance."""
        if self.timer > STRIKE_STEPS:
            self.advance(Stage.WATCH)
            return self.back_off(grip, puck)
        if self.timer == 1:  # the first step of the push (the line-up's step was the 0th)
            left = float((self.target - puck[:2]) @ self.line)
            self.size_now = self.size(self.hurry(left), puck[:2])
        contact = self.start(puck, 0.0)
        behind = float((contact - grip[:2]) @ self.motion)
        across = contact - grip[:2] - behind * self.motion
        action = self.move(grip, np.array([*(grip[:2] + across), puck[2]]))
        action[:2] += self.motion * self.size_now
        return np.append(np.clip(action, -1.0, 1.0), -1.0)

    def hurry(self, distance: float) -> float:
        """[m] how far the strike should send the puck to rest, for it to be within reach of the
        goal `distance` [m] away by the episode's last step: further than the goal if a glide that
        stops there would still be on its way (success is judged at the last step, not at rest)."""
        diagonal = is_diagonal(self.line)
        left = (self.horizon - self.steps - STRIKE_STEPS) * CONTROL_DT
        if not np.array_equal(self.target, self.goal) or left <= 0.0:
            return distance
        if glide_time(distance, diagonal, self.arrived) <= left:
            return distance
        # Be `arrived` short of the goal at the last step, still gliding: along an axis
        # x(t) = v t - a t^2 / 2; on the diagonal each axis does that at a / 2.
        rate = DECELERATION / 2.0 if diagonal else DECELERATION
        along = (distance - self.arrived) / (np.sqrt(2.0) if diagonal else 1.0)
        speed = along / left + rate * left / 2.0
        rest = speed * speed / (2.0 * rate)
        return float(rest * (np.sqrt(2.0) if diagonal else 1.0))

    def size(self, distance: float, puck: np.ndarray) -> float:
        """The strike's action size to send the puck at rest at `puck` [m, xy] `distance` [m] along the line."""
        return strike_size(distance, puck, self.line)

    def back_off(self, grip: np.ndarray, puck: np.ndarray) -> np.ndarray:
        """Away from the puck, back along the push and up a little."""
        return self.toward(grip, np.array([*(grip[:2] - self.motion * 0.03), puck[2] + 0.02]))

    def toward(self, grip: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The action moving the grip site towards `target`, fingers closed."""
        error = target - grip
        if np.linalg.norm(error) < 0.02:
            self.bias = np.clip(self.bias + self.integral * error, -0.02, 0.02)
        else:
            self.bias[:] = 0.0
        return np.append(self.move(grip, target + self.bias), -1.0)


def _clear(pucks: np.ndarray, grips: np.ndarray, distance: float) -> bool:
    """Whether each puck centre in `pucks` stays `distance` [m] from the fingers at the grip site
    position with the same index in `grips` (xy rows; either may be a single row)."""
    local = pucks - grips
    return bool(np.all(np.linalg.norm(local - np.clip(local, BOX[0], BOX[1]), axis=-1) >= distance))
