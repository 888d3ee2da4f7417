"""Experts that move the hand without grasping: reach, push, and hook-and-pull for drawers."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fetch.experts.base import Expert, Stage


class Reach(Expert):
    """Go straight to the goal and stay there."""

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        return np.append(self.move(grip, obs["desired_goal"]), 0.0)


class Push(Expert):
    """Get behind the object on the line to the goal, then push it along that line.

    Fingers closed, pushing a 5 cm block at its centre height. The hand goes over the object to
    the start point and only then down, so it never lands on the object. Once the object is within
    `done` of the goal the hand backs away: a policy that learnt to stand still there kept pushing a
    little and lost 10-14 % of its successes by step 50; backing away is a clear action to learn.
    """

    behind = 0.055
    """[m] the grip site's distance behind the object's centre when pushing."""
    done = 0.02
    """[m] the object this close to the goal: stop pushing..."""
    clear = 0.1
    """[m] ...and back away to this far from it."""
    speed = 0.8
    """[1] the push's largest action: policies learnt from its demos measured a little better than from
    slower pushes, and worse from faster ones, where the block strays more (docs/training.md)."""

    def line(self, obs: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]:
        """Grip, object and goal positions [m], the object's xy distance to the goal [m], and the
        unit xy direction from the object to the goal."""
        grip = self.part(obs, "grip_pos")
        obj = self.part(obs, "object_pos")
        goal = np.asarray(obs["desired_goal"])
        to_goal = (goal - obj)[:2]
        dist = float(np.linalg.norm(to_goal))
        return grip, obj, goal, dist, to_goal / max(dist, 1e-6)

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip, obj, goal, dist, direction = self.line(obs)
        if dist < self.done:
            # There: back away from the object and up, well clear of it.
            away = (grip - obj)[:2]
            away = away / max(float(np.linalg.norm(away)), 1e-6)
            self.advance(Stage.DONE)
            return np.append(self.move(grip, np.array([*(obj[:2] + away * self.clear), obj[2] + 0.05])), -1.0)
        if self.stage is Stage.DONE:
            self.stage = Stage.OVER  # the object left the goal: line up again
        start = obj[:2] - self.offset(direction)
        rel = grip[:2] - start
        along = float(rel @ direction) - self.behind
        across = float(abs(rel[0] * direction[1] - rel[1] * direction[0]))
        low, high = obj[2], obj[2] + 0.07
        if self.stage is Stage.PUSH and (across > 0.025 or along > -0.03):
            self.advance(Stage.OVER)  # the object turned away or the hand got past it: line up again
        if self.stage in (Stage.START, Stage.OVER):
            self.stage = Stage.OVER
            if np.linalg.norm(grip[:2] - start) < 0.01:
                self.advance(Stage.DOWN)
            else:
                lifted = grip[2] > low + 0.04 or np.linalg.norm(grip[:2] - obj[:2]) > 0.09
                target = np.array([*start, high]) if lifted else np.array([*grip[:2], high])
                return np.append(self.move(grip, target), -1.0)
        if self.stage is Stage.DOWN:
            if abs(grip[2] - low) < 0.01:
                self.advance(Stage.PUSH)
            return np.append(self.move(grip, np.array([*start, low])), -1.0)
        target = np.array([*(goal[:2] - self.offset(direction)), low])
        return np.append(self.move(grip, target, speed=self.speed), -1.0)

    def offset(self, direction: np.ndarray) -> np.ndarray:
        """[m] the object's centre minus the grip site's when pushing along `direction` (xy)."""
        return direction * self.behind


class Drawer(Expert):
    """Hook closed fingers into the gap behind the handle bar, then pull (or push) the drawer."""

    gap = 0.028
    """[m] the gap's centre from the bar's centre, towards the cabinet (+x)."""

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        handle = self.part(obs, "handle_pos")
        goal = np.asarray(obs["desired_goal"])
        hook = handle + [self.gap, 0.0, 0.0]
        if self.stage in (Stage.START, Stage.ABOVE):
            self.stage = Stage.ABOVE
            target = hook + [0.0, 0.0, 0.09]
            if np.linalg.norm((hook - grip)[:2]) < 0.006:
                self.advance(Stage.DOWN)
            return np.append(self.move(grip, target), -1.0)
        if self.stage is Stage.DOWN:
            if abs(hook[2] - grip[2]) < 0.008:
                self.advance(Stage.PULL)
            elif self.timer >= 4 and grip[2] - hook[2] > 0.015:
                self.advance(Stage.ABOVE)  # stalled: the fingers rest on the bar; up, and in again
            return np.append(self.move(grip, hook), -1.0)
        # Move the hook to where it is with the drawer at its goal, a bit past it.
        target = goal + [self.gap, 0.0, 0.0]
        target[0] += np.sign(target[0] - hook[0]) * 0.01
        return np.append(self.move(grip, target, speed=0.8), -1.0)
