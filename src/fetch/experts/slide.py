"""The Slide expert: put the puck on the goal's line with a push along y, then push it along x.

What it relies on (measured on Slide's table, friction 0.1):

- A puck gliding alone decelerates at `DECELERATION`, so from speed v it slides v^2 / (2 a)
  further. The hand can push it (at table height) only to x ~ 1.42 m; goals reach 1.69 m, so
  the puck must be let go at the speed that carries it the rest of the way.
- The closed fingers are a box, and a puck against a face rolls freely along it: a face pushes
  the puck along the face's normal (to within a degree) whichever way the hand moves, and a
  corner sends it 10-40 degrees off. So every push is along x or along y, with a face.
- Along x that face is the two fingertips side by side, with a slot between them. A puck pushed
  at the slot wedges into it: it prises the fingers ~8 mm apart, tilts up to 14 degrees and
  leaves sideways. So an x push uses one fingertip's face, the hand offset by `FINGER` across.
- A slow push is robust (the puck stays on the fingers and stops within a centimetre when the
  hand stops), a fast one is not: each push's speed follows the profile sqrt(2 a d) of the
  distance d left, capped, so the puck never carries more speed than it needs.
- The hand surges in the middle of each control step (the mocap target jumps once per step), so
  a pushed puck leaves up to ~1.5 times faster than the hand's end-of-step speed: the profile is
  scaled down, more along y, where an overshoot towards the table's side can strand the puck.
- Under action noise, every extra push risks more than it gains: the expert stops once the puck
  will rest within `arrived` of the goal, and pushes again only if it leaves `leave`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fetch.experts.base import Expert
from fetch.observation import CONTROL_DT

DECELERATION = 0.98
"""[m/s^2] a gliding puck's deceleration (friction 0.1 times g)."""
RADIUS = 0.025
"""[m] the puck's radius."""
FACE = (0.0135, 0.0149)
"""[m] the closed fingers' half extents along x and y around the grip site."""
FINGER = 0.0079
"""[m] each fingertip's centre across the hand (y) from the grip site; each is 14 mm wide."""


def glide(speed: float) -> float:
    """[m] how far a puck moving at `speed` [m/s] slides before it stops."""
    return max(speed, 0.0) ** 2 / (2.0 * DECELERATION)


def speed_to_glide(distance: float) -> float:
    """[m/s] the speed at which a puck slides `distance` [m] before it stops (0 if distance <= 0)."""
    return float(np.sqrt(2.0 * DECELERATION * max(distance, 0.0)))


class Slide(Expert):
    """Plan -> line up -> push -> watch, along y while the puck is off the goal's line, then x."""

    aligned = 0.025
    """[m] the puck counts as on the goal's line (y) within this."""
    arrived = 0.035
    """[m] no further push once the puck will rest this close to the goal..."""
    leave = 0.045
    """[m] ...until something moves it further than this (a correction risks more than it gains)."""
    gap = 0.012
    """[m] free space between the fingers and the puck where the hand comes down: under action
    noise the hand wanders a few mm a step, and a descending finger that touches the puck knocks it."""
    catch = 0.004
    """[m] how far a step the hand closes in on a puck at rest: the first touch is gentle."""
    hover = 0.06
    """[m] how high above the puck's centre the hand crosses over it."""
    close = 0.008
    """[m] the hand counts as at the start of a push within this."""
    at_rest = 0.03
    """[m/s] a puck slower than this counts as stopped."""
    ramp = 0.08
    """[m/s] how much faster the push may get each step."""
    slow = (0.45, 0.25)
    """[m/s] the push's speed (along x, y) where the hand can follow the puck all the way. Along y
    it is lower: a y push that overshoots towards the table's side can leave the puck where the
    hand cannot get round it."""
    short = 0.015
    """[m] the push aims to leave the puck this far short of the goal (but for the line-up of a shot
    beyond the hand's reach, which aims at the goal's line: see `push`)."""
    profile = (0.5, 0.5)
    """a push's speed (along x, y) as a fraction of the speed that would carry the puck just to the
    goal. The puck leaves faster than the hand: the hand surges in the middle of each control step."""
    feedback = 1.0
    """[1] how much of the puck's speed error the hand's next step corrects."""
    centred = 0.003
    """[m] how far the puck may drift across the face's middle before the hand follows it."""
    rolled = (0.009, FACE[0])
    """[m] the puck has rolled off the face (x push: one fingertip, y push: a finger's side) once
    its centre is this far across from the face's middle."""
    stretch = 1.49
    """[m] the furthest x where the hand gets down to the puck's height."""
    reach = 1.40
    """[m] the puck's centre x where a push along x should have let go (the arm's reach at table
    height, less a margin: the hand slows as the arm stretches)."""
    limit = 1.61
    """[m] the puck's centre x where the hand can push it no further (the grip site stops at
    x ~ 1.57 m at table height)."""

    def reset(self) -> None:
        super().reset()
        self.axis = 0
        self.sign = 1.0
        self.speed = 0.0
        self.line = 0.0
        self.descending = False
        self.hold = np.zeros(3)
        self.y_pushes = 0  # pushes along y started this episode

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        puck = self.part(obs, "object_pos")
        velocity = (self.part(obs, "object_velp") + self.part(obs, "grip_velp"))[:2] / CONTROL_DT
        goal = np.asarray(obs["desired_goal"])
        speed = float(np.linalg.norm(velocity))
        rest = puck[:2] + velocity / max(speed, 1e-9) * glide(speed)
        if self.stage == "watch" and self.timer < 2:
            return self.toward(grip, grip - self.direction() * 0.02)
        # Plan again until the hand comes down: a puck still gliding may stop elsewhere than
        # predicted, or the hand may have nudged it on the way round.
        if self.stage in ("start", "watch", "done") or (self.stage == "line_up" and not self.descending):
            self.plan(rest, goal, grip)
        if self.stage == "done":
            return self.toward(grip, self.hold)
        if self.stage == "line_up":
            return self.line_up(grip, puck, rest, speed)
        return self.push(grip, puck, goal, velocity)

    def direction(self) -> np.ndarray:
        unit = np.zeros(3)
        unit[self.axis] = self.sign
        return unit

    def plan(self, rest: np.ndarray, goal: np.ndarray, grip: np.ndarray) -> None:
        """Choose the next push from where the puck will come to rest."""
        error = goal[:2] - rest
        if np.linalg.norm(error) < (self.leave if self.stage == "done" else self.arrived):
            self.finish(grip, goal)
            return
        axis = 1 if abs(error[1]) > self.aligned else 0
        sign = float(np.sign(error[axis]) or 1.0)
        if self.stage != "line_up" or (axis, sign) != (self.axis, self.sign):
            self.axis, self.sign = axis, sign
            if self.behind(np.array([*rest, goal[2]]), self.gap)[0] > self.stretch:
                # Out of the hand's reach at the puck's height: an attempt would only knock it.
                self.finish(grip, goal)
                return
            self.advance("line_up")

    def finish(self, grip: np.ndarray, goal: np.ndarray) -> None:
        """No more pushes: hold still, clear above the puck (zero actions would let action noise
        walk the hand into it)."""
        if self.stage != "done":
            self.hold = np.array([*grip[:2], goal[2] + self.hover])
            self.advance("done")

    def across(self) -> float:
        """[m] where the face's middle lies across the push from the grip site: an x push uses the
        fingertip at +y (the slot between the fingertips would catch the puck)."""
        return FINGER if self.axis == 0 else 0.0

    def behind(self, puck: np.ndarray, gap: float) -> np.ndarray:
        """[m] where the grip site is when the face is `gap` behind `puck` (world xyz)."""
        start = puck - self.direction() * (RADIUS + FACE[self.axis] + gap)
        start[1 - self.axis] -= self.across()
        return start

    def line_up(self, grip: np.ndarray, puck: np.ndarray, rest: np.ndarray, speed: float) -> np.ndarray:
        """To the start behind where the puck will rest (over it if it is in the way), then down
        once the puck has stopped."""
        start = self.behind(np.array([*rest, puck[2]]), self.gap)
        off = float(np.linalg.norm(grip[:2] - start[:2]))
        if self.descending and off > 2 * self.close:
            self.descending = False  # knocked off the start: go round again
        if self.descending or (off < self.close and speed < self.at_rest):
            self.descending = True
            if abs(grip[2] - puck[2]) < 0.004:
                self.speed, self.line, self.descending = 0.0, float(grip[1 - self.axis]), False
                self.advance("push")
                self.y_pushes += self.axis == 1
            return self.toward(grip, start)
        high = puck[2] + self.hover
        clear = _distance_to_segment(puck[:2], grip[:2], start[:2]) > RADIUS + 0.035
        if clear and speed < self.at_rest:
            return self.toward(grip, start)
        if grip[2] < high - 0.02:
            # Low near the puck: rise first so the hand never sweeps across it.
            return self.toward(grip, np.array([*grip[:2], high]))
        return self.toward(grip, np.array([*start[:2], high]))

    def push(self, grip: np.ndarray, puck: np.ndarray, goal: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Push with a face at the profile's speed; let go once the puck will glide far enough."""
        unit = self.direction()
        short = self.short
        if self.axis == 1 and self.y_pushes == 1 and goal[0] > self.stretch:
            # Lining up a shot at a goal the hand cannot get down to: nothing corrects the line
            # afterwards and the shot drifts across on its own, so aim at the line itself (a
            # landing a little past it is still on it, within `aligned`). Not when correcting a
            # line-up that missed: pushes that imprecise would ping-pong across the line.
            short = 0.0
        left = float((goal - puck)[self.axis]) * self.sign
        along = float(velocity[self.axis]) * self.sign
        # Let go once the puck will glide far enough, a step early (the hand answers one step
        # later and the puck moves on meanwhile), or if it rolled off the fingers' face.
        drift = float(puck[1 - self.axis]) - self.line - self.across()
        rolled_off = abs(drift) > self.rolled[self.axis]
        if rolled_off or left - glide(along) - along * CONTROL_DT <= short:
            self.advance("watch")
            return self.toward(grip, grip - unit * 0.02)
        # The speed that, let go where the hand must stop, carries the puck to the goal.
        beyond = self.sign * (goal[0] - self.reach) - short if self.axis == 0 else 0.0
        launch = speed_to_glide(beyond)
        # Below the speed at which it would just glide to the goal (bumps leave it faster).
        profile = self.profile[self.axis] * speed_to_glide(left - short)
        # ...but never below the speed that carries it on from where the arm runs out.
        last = self.sign * (goal[0] - self.limit) - short if self.axis == 0 else 0.0
        floor = speed_to_glide(last)
        self.speed = min(max(self.slow[self.axis], launch), max(profile, floor), self.speed + self.ramp)
        # The hand drives the puck a little faster than its target moves: correct by what it does.
        drive = max(self.speed + self.feedback * (self.speed - along), 0.0) if along > 0.1 else self.speed
        # From the puck's contact point (or the hand, if it lags), on the line the push started on.
        lead = max(float((self.behind(puck, 0.0) - grip) @ unit), 0.0)
        if along < self.at_rest:
            lead = min(lead, self.catch)
        target = grip + unit * (lead + drive * CONTROL_DT)
        # Keep the puck near the face's middle: follow its drift across beyond that.
        if abs(drift) > self.centred:
            self.line += drift - np.sign(drift) * self.centred
        target[1 - self.axis] = self.line
        target[2] = puck[2]
        return self.toward(grip, target)

    def toward(self, grip: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The action moving the grip site towards `target`, fingers closed."""
        return np.append(self.move(grip, target), -1.0)


def _distance_to_segment(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """[m] the distance from `point` to the segment a-b (xy)."""
    ab = b - a
    t = float(np.clip((point - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(point - (a + t * ab)))
