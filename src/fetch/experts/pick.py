"""Pick-and-place experts: approach, grasp, lift, carry, place, release (PickPlace, bins, boxes)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from fetch.experts.base import Expert, Stage


@dataclasses.dataclass(frozen=True)
class Grasp:
    """How one task's object is picked and placed. Heights are world z [m]."""

    obj: str
    """observation part prefix: "object", "block", "lid"."""
    grip_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """[m] where the grip site goes relative to the object's position to grasp it."""
    opening: float = 0.05
    """[m] finger opening for the approach (each finger, 0.05 is fully open)."""
    hover: float = 0.06
    """[m] approach height above the grasp point."""
    carry_z: float = 0.0
    """[m] lowest grip height while carrying (clears walls and rims); 0: no minimum."""
    release: bool = False
    """let go at the goal (place) instead of holding the object there."""
    release_tolerance: float = 0.01
    """[m] how close the object must be to the goal before letting go."""


class PickAndPlace(Expert):
    """A state machine: open -> above -> descend -> close -> lift/carry -> lower -> release -> retreat."""

    def __init__(self, layout: Mapping[str, slice], grasp: Grasp, gain: float = 1.0) -> None:
        self.grasp = grasp
        super().__init__(layout, gain)

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        g = self.grasp
        grip = self.part(obs, "grip_pos")
        obj = self.part(obs, f"{g.obj}_pos")
        goal = np.asarray(obs["desired_goal"])
        offset = np.asarray(g.grip_offset)
        grasp_at = obj + offset
        fingers = self.part(obs, "gripper_state").mean()
        held = np.linalg.norm(obj + offset - grip) < 0.03 and fingers < g.opening * 0.95

        if self.stage is Stage.START:
            self.advance(Stage.ABOVE)
        if self.stage in (Stage.LIFT, Stage.CARRY, Stage.LOWER) and not held:
            self.advance(Stage.ABOVE)  # dropped it: start over
        if self.stage is Stage.ABOVE:
            target = grasp_at + [0.0, 0.0, g.hover]
            target[2] = max(target[2], grip[2] if np.linalg.norm((grasp_at - grip)[:2]) > 0.02 else 0.0)
            xyz = self.move(grip, target)
            if np.linalg.norm((grasp_at - grip)[:2]) < 0.008:
                self.advance(Stage.DESCEND)
            return np.append(xyz, self.finger_servo(obs, self.layout, g.opening))
        if self.stage is Stage.DESCEND:
            xyz = self.move(grip, grasp_at)
            # Drifted off, or stalled above the grasp point: fingers that noise or a bump closed
            # on the way down rest on the object's top. Go back up, open them and come down again.
            if np.linalg.norm((grasp_at - grip)[:2]) > 0.02 or (self.timer >= 4 and grip[2] - grasp_at[2] > 0.015):
                self.advance(Stage.ABOVE)
            elif abs(grasp_at[2] - grip[2]) < 0.006:
                self.advance(Stage.CLOSE)
            return np.append(xyz, self.finger_servo(obs, self.layout, g.opening))
        if self.stage is Stage.CLOSE:
            if self.timer >= 3:
                self.advance(Stage.LIFT)
                # Lift clear of rims and off the table before moving sideways.
                self.lift_z = max(g.carry_z, grip[2] + 0.03)
            return np.append(self.move(grip, grasp_at), -1.0)
        place = goal + offset
        if self.stage is Stage.LIFT:
            target = np.array([grip[0], grip[1], self.lift_z])
            if grip[2] >= self.lift_z - 0.01:
                self.advance(Stage.CARRY)
            return np.append(self.move(grip, target), -1.0)
        if self.stage is Stage.CARRY:
            target = place.copy()
            # Carried, not dragged: stay at the lift height until above the goal (a block pushed
            # along the table slips out of fingers that press on it; LOWER sets it down).
            target[2] = max(target[2], g.carry_z, self.lift_z)
            if np.linalg.norm((place - grip)[:2]) < 0.01:
                self.advance(Stage.LOWER)
            return np.append(self.move(grip, target), -1.0)
        if self.stage is Stage.LOWER:
            if g.release and np.linalg.norm(obj - goal) < g.release_tolerance:
                self.advance(Stage.RELEASE)
            return np.append(self.move(grip, place), -1.0)
        if self.stage is Stage.RELEASE:
            if self.timer >= 3:
                self.advance(Stage.RETREAT)
            return np.append(np.zeros(3), 1.0)
        # retreat: straight up, fingers open, then hold still
        target = grip.copy()
        target[2] = max(grip[2], place[2] + 0.08) if self.timer < 3 else grip[2]
        return np.append(self.move(grip, target), 1.0)
