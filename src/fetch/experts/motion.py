"""Experts that move the hand without grasping: reach, push, slide, and hook-and-pull for drawers."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fetch.experts.base import Expert
from fetch.observation import CONTROL_DT
from fetch.robot import ACTION_STEP


class Reach(Expert):
    """Go straight to the goal and stay there."""

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        return np.append(self.move(grip, obs["desired_goal"]), 0.0)


class Push(Expert):
    """Get behind the object on the line to the goal, then push it along that line.

    Fingers closed, pushing a 5 cm block at its centre height. The hand goes over the object to
    the start point and only then down, so it never lands on the object.
    """

    behind = 0.055
    """[m] the grip site's distance behind the object's centre when pushing."""

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
        start = obj[:2] - self.offset(direction)
        rel = grip[:2] - start
        along = float(rel @ direction) - self.behind
        across = float(abs(rel[0] * direction[1] - rel[1] * direction[0]))
        low, high = obj[2], obj[2] + 0.07
        if self.stage == "push" and (across > 0.025 or along > -0.03):
            self.advance("over")  # the object turned away or the hand got past it: line up again
        if self.stage in ("start", "over"):
            self.stage = "over"
            if np.linalg.norm(grip[:2] - start) < 0.01:
                self.advance("down")
            else:
                lifted = grip[2] > low + 0.04 or np.linalg.norm(grip[:2] - obj[:2]) > 0.09
                target = np.array([*start, high]) if lifted else np.array([*grip[:2], high])
                return np.append(self.move(grip, target), -1.0)
        if self.stage == "down":
            if abs(grip[2] - low) < 0.01:
                self.advance("push")
            return np.append(self.move(grip, np.array([*start, low])), -1.0)
        if dist < 0.01:
            return np.append(np.zeros(3), -1.0)
        target = np.array([*(goal[:2] - self.offset(direction)), low])
        return np.append(self.move(grip, target, speed=0.6), -1.0)

    def offset(self, direction: np.ndarray) -> np.ndarray:
        """[m] the object's centre minus the grip site's when pushing along `direction` (xy)."""
        return direction * self.behind


class Slide(Push):
    """Knock the puck towards the goal with aimed bumps, never faster than it can stop at the goal.

    The hand, driven through a mocap target, surges and stops within each 40 ms step, so it
    moves the puck by a series of bumps, each an impulse along the contact normal. The closed
    fingers are a 2.7 x 3 cm rectangle: a face would push only along its own normal, so each
    step the hand puts a corner behind the puck on the line from the goal through the puck's
    centre and pushes through it. A puck gliding alone decelerates at a ~ mu g, and sqrt(2 a d)
    is the speed at which it glides exactly the distance d left; the hand never pushes faster,
    so where it must stop (the workspace ends at x = 1.5 m) the puck glides on to the goal.
    """

    radius = 0.025
    """[m] the puck's radius."""
    half = (0.0135, 0.0149)
    """[m] the closed fingers' half extents (x, y) around the grip site."""
    deceleration = 0.96
    """[m/s^2] the puck's measured deceleration when gliding alone."""
    full_speed = ACTION_STEP / CONTROL_DT
    """[m/s] the hand's speed at |a| = 1."""
    ramp = 0.12
    """[m/s] how much faster the hand may push each step."""
    short = 0.025
    """[m] aim to stop the puck this far short of the goal: the last bump adds a little speed."""

    def offset(self, direction: np.ndarray) -> np.ndarray:
        corner = np.array([np.sign(direction[0]) * self.half[0], np.sign(direction[1]) * self.half[1]])
        return direction * (self.radius + 0.003) + corner

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip, obj, goal, dist, direction = self.line(obs)
        velocity = (self.part(obs, "object_velp") + self.part(obs, "grip_velp"))[:2] / CONTROL_DT
        moving = float(np.linalg.norm(velocity)) > 0.03
        glide = max(float(velocity @ direction), 0.0) ** 2 / (2 * self.deceleration)
        if dist < 0.02 or (moving and glide >= dist - self.short):
            # It is there, or will glide there: keep the hand still, out of its way.
            return np.append(self.move(grip, grip), -1.0)
        if self.stage != "push":
            if moving:  # let a gliding puck come to rest before lining up again
                return np.append(self.move(grip, grip), -1.0)
            return super().act(obs)
        behind = obj[:2] - self.offset(direction)
        if not moving and np.linalg.norm(grip[:2] - behind) > 0.03:
            self.advance("over")  # the puck stopped short or off the line: line up again
            return np.append(self.move(grip, grip), -1.0)
        # Bumps leave the puck a little faster than the hand: push at 85 % of the profile.
        profile = 0.85 * np.sqrt(2 * self.deceleration * max(dist - self.short, 0.0))
        speed = min(self.full_speed, profile, self.ramp * (self.timer + 1))
        target = np.array([*(behind + direction * speed * CONTROL_DT), obj[2]])
        return np.clip(np.append(self.move(grip, target), -1.0), -1.0, 1.0)


class Drawer(Expert):
    """Hook closed fingers into the gap behind the handle bar, then pull (or push) the drawer."""

    gap = 0.028
    """[m] the gap's centre from the bar's centre, towards the cabinet (+x)."""

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        handle = self.part(obs, "handle_pos")
        goal = np.asarray(obs["desired_goal"])
        hook = handle + [self.gap, 0.0, 0.0]
        if self.stage in ("start", "above"):
            self.stage = "above"
            target = hook + [0.0, 0.0, 0.09]
            if np.linalg.norm((hook - grip)[:2]) < 0.006:
                self.advance("down")
            return np.append(self.move(grip, target), -1.0)
        if self.stage == "down":
            if abs(hook[2] - grip[2]) < 0.008:
                self.advance("pull")
            return np.append(self.move(grip, hook), -1.0)
        # Move the hook to where it is with the drawer at its goal, a bit past it.
        target = goal + [self.gap, 0.0, 0.0]
        target[0] += np.sign(target[0] - hook[0]) * 0.01
        return np.append(self.move(grip, target, speed=0.8), -1.0)
