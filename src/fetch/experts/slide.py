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
FINGER = 0.0079
"""[m] each fingertip's centre across the hand (y) from the grip site; each is 14 mm wide."""


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
    """Plan -> line up -> push -> watch: an axis push onto the goal's diagonal, then the shot."""

    arrived = 0.03
    """[m] no further push once the puck will rest this close to the goal..."""
    leave = 0.045
    """[m] ...until something moves it further than this (a correction risks more than it gains)."""
    on_line = 0.015
    """[m] the goal counts as on a diagonal (or an axis) from the puck within this across."""
    gap = 0.012
    """[m] free space between the fingers and the puck where the hand comes down."""
    hover = 0.05
    """[m] how high above the puck's centre the hand crosses over it."""
    margin = 0.006
    """[m] the fingers pass the puck at least this far off when they stay low."""
    close = 0.006
    """[m] the hand counts as at the start of a push within this."""
    at_rest = 0.05
    """[m/s] a puck slower than this counts as stopped."""
    ramp = 0.25
    """[m/s] how much faster the push may get each step."""
    slow = 0.45
    """[m/s] the top speed of a push that puts the puck on the diagonal."""
    fast = 1.0
    """[m/s] the top speed of a shot."""
    reach = 1.36
    """[m] the furthest the puck's centre x can be pushed to (the hand stops at x ~ 1.39 m)."""
    lead = 1.0
    """[steps] the release comes this many steps of the puck's motion before its glide would do."""
    catch = 0.004
    """[m] how far a step the hand closes in on a puck at rest."""
    lag = 2.0
    """[1] the hand covers about 1 / lag of its target's offset in a step."""
    feedback = 0.5
    """[1] how much of the puck's speed error the hand's next step corrects."""
    """[steps] the release comes this many steps of the puck's motion before its glide would do."""

    def reset(self) -> None:
        super().reset()
        self.push_dir = np.array([1.0, 0.0])
        self.contact = np.zeros(2)
        self.target = np.zeros(2)
        self.shot = False
        self.speed = 0.0
        self.descending = False
        self.hold = np.zeros(3)
        self.pushes = 0

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        puck = self.part(obs, "object_pos")
        velocity = (self.part(obs, "object_velp") + self.part(obs, "grip_velp"))[:2] / CONTROL_DT
        goal = np.asarray(obs["desired_goal"])
        rest = puck[:2] + glide(velocity)
        if self.stage == "watch" and self.timer < 2:
            return self.toward(grip, np.array([*(grip[:2] - self.push_dir * 0.03), puck[2] + 0.02]))
        if self.stage in ("start", "watch", "done") or (self.stage == "line_up" and not self.descending):
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
        if abs(dy) < self.on_line or abs(dx) < self.on_line:
            # On an axis: shoot along it.
            direction, target, shot = (np.array([sx, 0.0]) if abs(dy) < self.on_line
                                       else np.array([0.0, sy])), goal[:2], True
        elif abs(abs(dx) - abs(dy)) < self.on_line:
            direction, target, shot = np.array([sx, sy]) / np.sqrt(2.0), goal[:2], True
        elif abs(dy) > abs(dx):
            # Along y until the goal is on the diagonal.
            direction, target, shot = np.array([0.0, sy]), np.array([rest[0], goal[1] - sy * abs(dx)]), False
        elif goal[0] - sx * abs(dy) <= self.reach:
            # Along x until the goal is on the diagonal.
            direction, target, shot = np.array([sx, 0.0]), np.array([goal[0] - sx * abs(dy), rest[1]]), False
        else:
            # The x push would end beyond the hand's reach: the diagonal first, then a shot along x.
            direction = np.array([sx, sy]) / np.sqrt(2.0)
            target, shot = np.array([rest[0] + sx * abs(dy), goal[1]]), False
        changed = not np.allclose(direction, self.push_dir) or self.stage != "line_up"
        self.push_dir, self.target, self.shot = direction, target, shot
        self.contact = self.contact_point(direction)
        if changed:
            self.advance("line_up")

    def contact_point(self, direction: np.ndarray) -> np.ndarray:
        """[m] the point of the fingers (from the grip site, xy) that pushes along `direction`."""
        if direction[1] == 0.0:
            return np.array([np.sign(direction[0]) * FRONT, FINGER])
        if direction[0] == 0.0:
            return np.array([MIDDLE, SIDES[0] if direction[1] > 0 else SIDES[1]])
        return np.array([np.sign(direction[0]) * FRONT, SIDES[0] if direction[1] > 0 else SIDES[1]])

    def finish(self, grip: np.ndarray, goal: np.ndarray) -> None:
        """No more pushes: hold still, clear above the puck."""
        if self.stage != "done":
            self.hold = np.array([*grip[:2], goal[2] + self.hover])
            self.advance("done")

    def start(self, puck: np.ndarray, gap: float) -> np.ndarray:
        """[m] where the grip site is when the contact point is `gap` behind the puck (xy)."""
        return puck[:2] - self.push_dir * (RADIUS + gap) - self.contact

    def line_up(self, grip: np.ndarray, puck: np.ndarray, rest: np.ndarray, speed: float) -> np.ndarray:
        """To the start behind where the puck will rest (over it if it is in the way), then down
        once the puck has stopped."""
        start = self.start(np.array([*rest, puck[2]]), self.gap)
        off = float(np.linalg.norm(grip[:2] - start))
        if self.descending and off > 2 * self.close:
            self.descending = False
        if self.descending or (off < self.close and speed < self.at_rest):
            self.descending = True
            if abs(grip[2] - puck[2]) < 0.007:
                self.speed, self.descending = 0.0, False
                self.pushes += 1
                self.advance("push")
            return self.toward(grip, np.array([*start, puck[2]]))
        high = puck[2] + self.hover
        if speed < self.at_rest and _clear(puck[:2], grip[:2], start, RADIUS + self.margin):
            return self.toward(grip, np.array([*start, puck[2]]))
        if grip[2] < high - 0.02:
            return self.toward(grip, np.array([*grip[:2], high]))
        return self.toward(grip, np.array([*start, high]))

    def push(self, grip: np.ndarray, puck: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Push with the contact point at the profile's speed; let go once the puck will glide to
        the target, or where the hand can go no further."""
        unit = self.push_dir
        left = float((self.target - puck[:2]) @ unit)
        along = float(velocity @ unit)
        ahead = float(glide(velocity) @ unit) + self.lead * along * CONTROL_DT
        if ahead >= left or (unit[0] > 0 and puck[0] > self.reach and along > 0):
            self.advance("watch")
            return self.toward(grip, np.array([*(grip[:2] - unit * 0.03), puck[2] + 0.02]))
        need = float(np.linalg.norm(launch(unit * left)))
        contact = self.start(puck, 0.0)
        behind = max(float((contact - grip[:2]) @ unit), 0.0)
        across = contact - grip[:2] - behind * unit
        if along < self.at_rest:
            # Close in gently: a hand that hits the puck at speed bounces it off faster still.
            self.speed = 0.0
            step = min(behind, self.catch) + self.catch
        else:
            top = self.fast if self.shot else self.slow
            self.speed = min(self.speed + self.ramp, top, max(need, 0.1))
            # The hand lags its target (it covers about 1 / `lag` of the offset per step).
            step = behind + self.lag * (self.speed + self.feedback * (self.speed - along)) * CONTROL_DT
        target = grip[:2] + unit * max(step, 0.0) + across
        return self.toward(grip, np.array([*target, puck[2]]))

    def toward(self, grip: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The action moving the grip site towards `target`, fingers closed."""
        return np.append(self.move(grip, target), -1.0)


BOX = (np.array([-0.0164, SIDES[1]]), np.array([FRONT, SIDES[0]]))
"""[m] the closed fingers' extent (xy) from the grip site: low, high corners."""


def _clear(puck: np.ndarray, a: np.ndarray, b: np.ndarray, distance: float) -> bool:
    """Whether the fingers, moving from grip a to grip b (xy), stay `distance` [m] from the puck's centre."""
    for t in np.linspace(0.0, 1.0, 9):
        local = puck - (a + t * (b - a))
        if np.linalg.norm(local - np.clip(local, BOX[0], BOX[1])) < distance:
            return False
    return True
