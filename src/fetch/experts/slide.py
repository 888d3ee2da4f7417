"""The Slide expert: push the puck along an axis onto a diagonal through the goal, then shoot it.

What it relies on (measured on Fetch*-v4's Slide table, friction 0.1, MuJoCo's default pyramidal
friction cone):

- Friction on the table is not isotropic. A gliding puck decelerates at `DECELERATION` along the
  larger of its x and y velocity components only, the smaller one kept, until both are equal;
  then both at half that. From a launch (A, B), A >= B >= 0, it comes to rest (A^2 + B^2) / 2a
  further along A's axis and A B / a along B's (`glide`): a glide along an axis stays on it, any
  other bends towards the nearest diagonal, and along the diagonal the puck goes sqrt(2) times
  further than along an axis for the same speed.
- Pushed, the puck follows the same rule: a face of the closed fingers pushes it along the face's
  normal (the puck rolls along the face) and the fingers' corner pushes it along the diagonal.
  So the pushes here go along x, along y, or along a diagonal, and nothing else is aimed.
- Along x the face is the two fingertips side by side with a slot between them: a puck pushed at
  the slot wedges into it, so an x push uses one fingertip, the hand offset by `FINGER` across.
- The plan: from where the puck will rest, one axis push that leaves the goal on a diagonal (or on
  the axis) from the puck, then a shot along that diagonal (or axis), let go at the speed whose
  glide ends on the goal. The diagonal shot is forgiving: a glide that starts a little off the
  diagonal bends back onto it. The hand reaches only x ~ 1.39 m at table height, so when the axis
  push would have to end beyond that, the diagonal goes first and the shot is along x.
- The hand surges in the middle of each control step (the mocap target jumps once per step), so
  a pushed puck leaves up to ~1.5 times faster than the hand: the release watches the puck's own
  speed and lets go a step before its glide would reach the target.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fetch.experts.base import Expert
from fetch.observation import CONTROL_DT

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
    """Plan -> line up -> push -> watch: a push onto a line through the goal, then the shot."""

    arrived = 0.03
    """[m] no further push once the puck will rest this close to the goal..."""
    leave = 0.045
    """[m] ...until something moves it further than this (a correction risks more than it gains)."""
    on_line = 0.02
    """[m] the goal counts as on a diagonal (or an axis) from the puck within this across."""
    gap = 0.010
    """[m] free space between the fingers and the puck where the hand comes down."""
    hover = 0.045
    """[m] how high above the puck's centre the hand crosses over it."""
    margin = 0.006
    """[m] the fingers pass the puck at least this far off when they stay low."""
    close = 0.006
    """[m] the hand counts as at the start of a push within this."""
    aligned = 0.0025
    """[m] ...and within this across the strike (the face or corner it strikes with is a few mm wide)."""
    at_rest = 0.05
    """[m/s] a puck slower than this counts as stopped."""
    catch = 0.006
    """[m] how far a step the hand closes in on a puck at rest."""
    ramp = 0.3
    """[1] how much larger the push's action may get each step."""
    strike = 0.9
    """[m/s] the speed a puck pushed with an action of size 1 leaves at (0.46, 0.68, 0.98 m/s after
    two steps at 0.5, 0.7, 1 from rest, x ~ 1 m; 10% less at x ~ 1.2 m)."""
    feedback = 0.0
    """[1] how much of the puck's speed error the next step's action corrects."""
    profile = 1.0
    """[1] the push's speed as a fraction of the speed whose glide would end on its target (the
    puck leaves faster than the hand: see the module's docstring)."""
    lead = 1.0
    """[steps] the release comes this many steps of the puck's motion before its glide would do."""
    lost = 0.04
    """[m] the push is over once the puck is this far ahead of the fingers (it got away)."""
    reach = 1.36
    """[m] the furthest the puck's centre x can be pushed to (the hand stops at x ~ 1.39 m)."""
    integral = 0.3
    """[1] the fraction of its error the hand's target adds up each step (a stretched arm stalls short
    of a target a few mm away)."""

    def reset(self) -> None:
        super().reset()
        self.line = np.array([1.0, 0.0])  # where the push sends the puck (unit, xy)
        self.motion = np.array([1.0, 0.0])  # where the hand moves during the push (unit, xy)
        self.offset = np.zeros(2)  # the puck's centre from the grip site at contact (xy)
        self.target = np.zeros(2)
        self.shot = False
        self.speed = 0.0
        self.hold = np.zeros(3)
        self.bias = np.zeros(3)
        self.pushes = 0

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        puck = self.part(obs, "object_pos")
        velocity = (self.part(obs, "object_velp") + self.part(obs, "grip_velp"))[:2] / CONTROL_DT
        goal = np.asarray(obs["desired_goal"])
        rest = puck[:2] + glide(velocity)
        if self.stage == "watch" and self.timer < 2:
            return self.back_off(grip, puck)
        if self.stage in ("start", "watch", "done") or self.stage == "line_up":
            self.plan(rest, goal, grip)
        if self.stage == "done":
            return self.toward(grip, self.hold)
        if self.stage == "line_up":
            return self.line_up(grip, puck, rest, float(np.linalg.norm(velocity)))
        return self.push(grip, puck, velocity)

    def plan(self, rest: np.ndarray, goal: np.ndarray, grip: np.ndarray) -> None:
        """Choose the next push from where the puck will come to rest."""
        error = goal[:2] - rest
        if np.linalg.norm(error) < (self.leave if self.stage == "done" else self.arrived):
            self.finish(grip, goal)
            return
        dx, dy = float(error[0]), float(error[1])
        sx, sy = float(np.sign(dx) or 1.0), float(np.sign(dy) or 1.0)
        diagonal = np.array([sx, sy]) / np.sqrt(2.0)
        if abs(dy) < self.on_line:
            line, target, shot = np.array([sx, 0.0]), goal[:2], True
        elif abs(abs(dx) - abs(dy)) < self.on_line:
            line, target, shot = diagonal, goal[:2], True
        elif abs(dx) < self.on_line:
            line, target, shot = np.array([0.0, sy]), goal[:2], True
        else:
            line, target, shot = self.two_strikes(rest, goal[:2])
        changed = not np.allclose(line, self.line) or self.stage != "line_up"
        self.line, self.target, self.shot = line, target, shot
        self.motion, self.offset = self.contact(line)
        if changed:
            self.advance("line_up")

    def two_strikes(self, rest: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
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
            return max(first - first_reach, second - second_reach, 0.0), first

        line, target = min(plans, key=shortfall)[:2]
        return line, target, False

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
        if self.stage != "done":
            self.hold = np.array([*grip[:2], goal[2] + self.hover])
            self.advance("done")

    def start(self, puck: np.ndarray, gap: float) -> np.ndarray:
        """[m] where the grip site is when the fingers are `gap` behind the puck (xy)."""
        return puck[:2] - self.offset - self.motion * gap

    def line_up(self, grip: np.ndarray, puck: np.ndarray, rest: np.ndarray, speed: float) -> np.ndarray:
        """To the start behind where the puck will rest, low if neither the hand's way there nor
        the puck's way to rest crosses the other, else over the puck; strike once it has stopped."""
        start = self.start(rest, self.gap)
        off = float(np.linalg.norm(grip[:2] - start))
        low = abs(grip[2] - puck[2]) < 0.007
        gliding = _clear_path(puck[:2], rest, start, RADIUS + self.margin)
        across = float(np.linalg.norm((grip[:2] - start) - ((grip[:2] - start) @ self.motion) * self.motion))
        if low and off < self.close and across < self.aligned and speed < self.at_rest:
            self.speed = 0.0
            self.pushes += 1
            self.advance("push")
            return self.toward(grip, np.array([*start, puck[2]]))
        if gliding and _clear(puck[:2], grip[:2], start, RADIUS + self.margin):
            return self.toward(grip, np.array([*start, puck[2]]))
        high = puck[2] + self.hover
        if grip[2] < high - 0.02:
            return self.toward(grip, np.array([*grip[:2], high]))
        return self.toward(grip, np.array([*start, high]))

    def push(self, grip: np.ndarray, puck: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Strike: `STRIKE_STEPS` steps of one action along the motion, sized for the distance."""
        if self.timer > STRIKE_STEPS:
            self.advance("watch")
            return self.back_off(grip, puck)
        if self.timer == 1:  # the first step of the push (the line-up's step was the 0th)
            left = float((self.target - puck[:2]) @ self.line)
            self.speed = self.size(left, float(puck[0]))
        contact = self.start(puck, 0.0)
        behind = float((contact - grip[:2]) @ self.motion)
        across = contact - grip[:2] - behind * self.motion
        action = self.move(grip, np.array([*(grip[:2] + across), puck[2]]))
        action[:2] += self.motion * self.speed
        return np.append(np.clip(action, -1.0, 1.0), -1.0)

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


BOX = (np.array([-0.0164, SIDES[1]]), np.array([FRONT, SIDES[0]]))
"""[m] the closed fingers' extent (xy) from the grip site: low, high corners."""


def _clear_path(puck: np.ndarray, rest: np.ndarray, grip: np.ndarray, distance: float) -> bool:
    """Whether a puck gliding from `puck` to `rest` stays `distance` [m] from fingers at `grip` (xy)."""
    for t in np.linspace(0.0, 1.0, 9):
        local = puck + t * (rest - puck) - grip
        if np.linalg.norm(local - np.clip(local, BOX[0], BOX[1])) < distance:
            return False
    return True


def _clear(puck: np.ndarray, a: np.ndarray, b: np.ndarray, distance: float) -> bool:
    """Whether the fingers, moving from grip a to grip b (xy), stay `distance` [m] from the puck's centre."""
    for t in np.linspace(0.0, 1.0, 9):
        local = puck - (a + t * (b - a))
        if np.linalg.norm(local - np.clip(local, BOX[0], BOX[1])) < distance:
            return False
    return True
