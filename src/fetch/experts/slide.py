"""The Slide expert: strike the puck onto a line through the goal, then strike it along that line.

What it relies on (measured on Fetch*-v4's Slide table, friction 0.1, MuJoCo's default pyramidal
friction cone; benchmarks/slide_reach.py searches what one or two strikes can reach):

- Friction on the table is not isotropic. A gliding puck decelerates at `DECELERATION` along the
  larger of its x and y velocity components only, the smaller one kept, until both are equal;
  then both at half that. From a launch (A, B), A >= B >= 0, it comes to rest (A^2 + B^2) / 2a
  further along A's axis and A B / a along B's (`glide`): a glide along an axis stays on it, any
  other bends towards the nearest diagonal, where it stays.
- Pushed, the puck obeys the same rule: a face of the closed fingers sends it along the face's
  normal (it rolls along the face) and their outer corner sends it along the diagonal, whichever
  way the hand moves. So the puck goes along x, along y or along a diagonal, nothing else.
- Along x the face is the two fingertips side by side with a slot between them: a puck struck
  at the slot wedges into it and tips up, so an x strike uses one fingertip (`FINGER`); a corner
  strike has the puck's centre `CORNER` past the fingers' side. Both strike with the hand moving
  along x from rest 1 cm behind the puck.
- A strike is two steps of one action: the mocap target jumps by 5 cm a step at full size and the
  hand surges, so the puck leaves at up to ~1 m/s, faster than the hand ever moves steadily. How
  far it then goes was measured against the action's size and the puck's x (the arm weakens as it
  stretches, and cannot reach a puck beyond x ~ 1.36 m): `strike_size`, `strike_reach`.
- The plan: from where the puck will rest, a shot if the goal is on an axis or a diagonal from
  it; else a first strike that leaves the goal on one (along x then the diagonal, or along the
  diagonal then x; for goals mostly across, along y then the diagonal), whichever pair the strike
  table says fits; the next plan starts from where the puck will rest.
- 50 steps are short: the hand lines up for the next strike while the puck still glides, low
  (below the puck's top) whenever neither the hand's way nor the puck's crosses the other; and
  success is judged at the last step, not at rest, so a shot that would still be gliding then is
  struck harder, to be near the goal at `horizon` (`hurry`: 80 % instead of 77 % on seeds 0-99).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fetch.experts.base import Expert, Stage
from fetch.timing import CONTROL_DT

DECELERATION = 0.98
"""[m/s^2] a puck gliding along an axis decelerates this much (friction 0.1 times g)."""
RADIUS = 0.025
"""[m] the puck's radius."""
FRONT = 0.0144
"""[m] the closed fingers' front face, along x from the grip site."""
SIDES = (0.0152, -0.0166)
"""[m] the closed fingers' +y and -y side faces, along y from the grip site."""
MIDDLE = -0.001
"""[m] the middle of the fingers' side faces, along x from the grip site."""
FINGER = 0.012
"""[m] where the puck's centre is across the hand (y) from the grip site when one fingertip pushes
it along x: on the +y fingertip (0.8 to 15.2 mm), off the slot between the two and off its corner."""
CORNER = 0.0088
"""[m] ...and how far past the fingers' side it is when their corner pushes it along the diagonal."""
BOX = (np.array([-0.0164, SIDES[1]]), np.array([FRONT, SIDES[0]]))
"""[m] the closed fingers' extent (xy) from the grip site: low, high corners."""

STRIKE_STEPS = 2
"""[steps] a strike is this many steps of one action, from rest 1 cm behind the puck."""
_SIZES = (0.15, 0.3, 0.5, 0.7, 0.9, 1.0)
_ROWS = (1.0, 1.15, 1.2, 1.25, 1.3, 1.36)
"""[m] the puck's x where the strikes below were measured: the arm weakens as it stretches."""
_ALONG_X = ((0.0, 0.055, 0.178, 0.328, 0.535, 0.645),
            (0.0, 0.055, 0.168, 0.317, 0.522, 0.616),
            (0.0, 0.044, 0.135, 0.252, 0.408, 0.494),
            (0.0, 0.020, 0.109, 0.218, 0.348, 0.442),
            (0.0, 0.001, 0.060, 0.142, 0.267, 0.337),
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
_ALONG_DIAGONAL = ((0.0, 0.022, 0.077, 0.167, 0.288, 0.350),
                   (0.0, 0.024, 0.077, 0.167, 0.293, 0.360),
                   (0.0, 0.019, 0.065, 0.139, 0.237, 0.287),
                   (0.0, 0.008, 0.047, 0.111, 0.195, 0.275),
                   (0.0, 0.000, 0.030, 0.060, 0.127, 0.171),
                   (0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def _strike_table(x: float, diagonal: bool) -> np.ndarray:
    """[m] how far a strike of each of `_SIZES` sends a puck at rest at `x` (per axis on a diagonal)."""
    rows = np.asarray(_ALONG_DIAGONAL if diagonal else _ALONG_X)
    return np.array([np.interp(x, _ROWS, rows[:, i]) for i in range(len(_SIZES))])


def strike_size(distance: float, x: float, diagonal: bool) -> float:
    """The action size whose strike sends a puck at rest at `x` [m] `distance` [m] (along x, or
    along the diagonal) before it stops; 1 if that is beyond any strike."""
    per_axis = distance / np.sqrt(2.0) if diagonal else distance
    return float(np.interp(per_axis, _strike_table(x, diagonal), _SIZES))


def strike_reach(x: float, diagonal: bool) -> float:
    """[m] the furthest a strike sends a puck at rest at `x` [m] (along x, or along the diagonal)."""
    furthest = float(_strike_table(x, diagonal)[-1])
    return furthest * np.sqrt(2.0) if diagonal else furthest


def _glide_time(distance: float, diagonal: bool, short: float = 0.0) -> float:
    """[s] how long a puck struck to glide `distance` [m] (along an axis or the diagonal) takes to
    come within `short` [m] of where it stops."""
    distance, short = max(distance, 0.0), min(max(short, 0.0), max(distance, 0.0))
    if diagonal:  # each axis decelerates at half the rate, over 1 / sqrt(2) of the distance
        return 2.0 * float(np.sqrt(DECELERATION * distance / np.sqrt(2.0))
                           - np.sqrt(DECELERATION * short / np.sqrt(2.0))) / DECELERATION
    return float(np.sqrt(2.0 * DECELERATION * distance) - np.sqrt(2.0 * DECELERATION * short)) / DECELERATION


def glide(velocity: np.ndarray) -> np.ndarray:
    """[m] where a puck moving at `velocity` [m/s, world xy] comes to rest, from where it is."""
    a, b = abs(float(velocity[0])), abs(float(velocity[1]))
    major, minor = (a * a + b * b) / (2.0 * DECELERATION), a * b / DECELERATION
    rest = np.array([major, minor]) if a >= b else np.array([minor, major])
    return rest * np.sign(velocity[:2])


def launch(displacement: np.ndarray) -> np.ndarray:
    """[m/s] the velocity whose glide ends `displacement` [m, world xy] away (`glide`'s inverse)."""
    x, y = abs(float(displacement[0])), abs(float(displacement[1]))
    s = np.sqrt(2.0 * DECELERATION * (x + y))
    t = np.sqrt(2.0 * DECELERATION * abs(x - y))
    major, minor = (s + t) / 2.0, (s - t) / 2.0
    speed = np.array([major, minor]) if x >= y else np.array([minor, major])
    return speed * np.where(np.asarray(displacement[:2]) < 0, -1.0, 1.0)


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

    def reset(self) -> None:
        super().reset()
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
        if abs(dy) < self.on_line:
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
        axis; the pair the strike tables say fits best, then the one whose first leg is shorter."""
        dx, dy = goal - rest
        sx, sy = float(np.sign(dx) or 1.0), float(np.sign(dy) or 1.0)
        diagonal = np.array([sx, sy]) / np.sqrt(2.0)
        x0, small, big = float(rest[0]), min(abs(dx), abs(dy)), abs(abs(dx) - abs(dy))
        plans = []
        if abs(dx) > abs(dy):
            # Along x onto the goal's diagonal, or along the diagonal onto the goal's y.
            plans.append((np.array([sx, 0.0]), np.array([goal[0] - sx * small, rest[1]]),
                          big, strike_reach(x0, False), small * np.sqrt(2.0), strike_reach(x0 + sx * big, True)))
            plans.append((diagonal, np.array([rest[0] + sx * small, goal[1]]),
                          small * np.sqrt(2.0), strike_reach(x0, True), big, strike_reach(x0 + sx * small, False)))
        else:
            # Along y onto the goal's diagonal, or along the diagonal onto the goal's x.
            plans.append((np.array([0.0, sy]), np.array([rest[0], goal[1] - sy * small]),
                          big, strike_reach(x0, False), small * np.sqrt(2.0), strike_reach(x0, True)))
            plans.append((diagonal, np.array([goal[0], rest[1] + sy * small]),
                          small * np.sqrt(2.0), strike_reach(x0, True), big, strike_reach(x0 + sx * small, False)))

        def shortfall(plan: tuple[np.ndarray, np.ndarray, float, float, float, float]) -> tuple[float, float]:
            first, first_reach, second, second_reach = plan[2:]
            diagonal_first = bool(plan[0][0] != 0.0 and plan[0][1] != 0.0)
            time = _glide_time(first, diagonal_first) + _glide_time(second, not diagonal_first, self.arrived)
            return max(first - first_reach, second - second_reach, 0.0), time

        line, target = min(plans, key=shortfall)[:2]
        return line, target

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
            self.size_now = self.size(self.hurry(left), float(puck[0]))
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
        diagonal = bool(self.line[0] != 0.0 and self.line[1] != 0.0)
        left = (self.horizon - self.steps - STRIKE_STEPS) * CONTROL_DT
        if not np.array_equal(self.target, self.goal) or left <= 0.0:
            return distance
        if _glide_time(distance, diagonal, self.arrived) <= left:
            return distance
        # Be `arrived` short of the goal at the last step, still gliding: along an axis
        # x(t) = v t - a t^2 / 2; on the diagonal each axis does that at a / 2.
        rate = DECELERATION / 2.0 if diagonal else DECELERATION
        along = (distance - self.arrived) / (np.sqrt(2.0) if diagonal else 1.0)
        speed = along / left + rate * left / 2.0
        rest = speed * speed / (2.0 * rate)
        return float(rest * (np.sqrt(2.0) if diagonal else 1.0))

    def size(self, distance: float, x: float) -> float:
        """The strike's action size to send the puck at rest at `x` [m] `distance` [m] along the line."""
        return strike_size(distance, x, diagonal=bool(self.line[0] != 0.0 and self.line[1] != 0.0))

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
