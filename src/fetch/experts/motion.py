"""Experts that move the hand without grasping: reach, push, slide, and hook-and-pull for drawers."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fetch.experts.base import Expert


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

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        obj = self.part(obs, "object_pos")
        goal = np.asarray(obs["desired_goal"])
        to_goal = (goal - obj)[:2]
        dist = float(np.linalg.norm(to_goal))
        direction = to_goal / max(dist, 1e-6)
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
    """Push the puck towards the goal with the hand's speed capped at sqrt(2 a d).

    A puck gliding alone on the 0.1-friction table decelerates at a ~ mu g, and sqrt(2 a d) is the
    speed at which it glides exactly the remaining distance d. A hand kept under that profile
    never outruns what the puck can stop from, and where the hand must stop (the workspace ends
    at x = 1.5 m) the puck glides on to the goal.
    """

    radius = 0.025 + 0.002
    """[m] the puck's radius plus a small gap."""
    half = (0.0135, 0.0149)
    """[m] the closed fingers' half extents (x, y) around the grip site: a rectangular pusher."""
    deceleration = 0.96
    """[m/s^2] the puck's measured deceleration when gliding alone."""
    full_speed = 0.05 / 0.04
    """[m/s] the hand's speed at |a| = 1."""
    ramp = 0.12
    """[m/s] how much faster the hand may go each step while pushing."""

    def offset(self, direction: np.ndarray) -> np.ndarray:
        # Finger-puck friction is 1, so a face pushing within 45 degrees of its normal holds the
        # puck without slipping: use the x face, or the y face for goals more to the side.
        axis = 0 if abs(direction[0]) >= abs(direction[1]) else 1
        offset = np.zeros(2)
        offset[axis] = np.sign(direction[axis]) * (self.half[axis] + self.radius)
        return offset

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        grip = self.part(obs, "grip_pos")
        obj = self.part(obs, "object_pos")
        moving = np.linalg.norm(self.part(obs, "object_velp") + self.part(obs, "grip_velp")) / 0.04 > 0.03
        if self.stage != "push":
            if moving:  # let a gliding puck come to rest before lining up again
                return np.append(self.move(grip, grip), -1.0)
            return super().act(obs)
        goal = np.asarray(obs["desired_goal"])
        to_goal = (goal - obj)[:2]
        dist = float(np.linalg.norm(to_goal))
        direction = to_goal / max(dist, 1e-6)
        if not moving and np.linalg.norm(grip[:2] - (obj[:2] - self.offset(direction))) > 0.03:
            self.advance("over")  # the puck stopped short or off the line: line up again
            return np.append(self.move(grip, grip), -1.0)
        # Speed up gently (a fast hand bounces the puck off), and never faster than the puck
        # could glide to a stop at the goal.
        profile = np.sqrt(2 * self.deceleration * max(dist - 0.005, 0.0))
        cap = min(self.full_speed, profile, self.ramp * (self.timer + 1)) / self.full_speed
        xyz = self.gain * (np.array([*(goal[:2] - self.offset(direction)), obj[2]]) - grip) / 0.05
        norm = float(np.linalg.norm(xyz[:2]))
        if norm > cap:
            xyz[:2] *= cap / norm
        return np.clip(np.append(xyz, -1.0), -1.0, 1.0)


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
