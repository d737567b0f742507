"""The privileged teacher: the scripted follower that swerves around obstacles, as actions of
the policy's own action type.

Training can add an imitation term that pulls the policy towards the teacher's action on every
state the policy itself visits (:func:`crllk.rl.loss.imitation_loss`), so the policy starts from a
driver that passes obstacles and Lagrangian PPO refines it. The teacher reads the true pose and
the map; the policy never does.
"""

from __future__ import annotations

import numpy as np

from crllk.maps.obstacles import ObstacleIndex
from crllk.sim.physics import Physics
from crllk.tasks.actions import duty_to_action
from crllk.tasks.config import TaskConfig
from crllk.tasks.follower import FollowerGains, LaneFollower


class Teacher:
    """The obstacle-avoiding follower of one task, answering in an action type."""

    def __init__(self, config: TaskConfig, obstacles: ObstacleIndex, action_type: str,
                 margin: float = FollowerGains.avoid_margin):
        """``margin``: the gap (m) kept between the robot's side and an obstacle's edge while
        passing it."""
        self.follower = LaneFollower(config.map, config.motor, obstacles=obstacles,
                                     gains=FollowerGains(avoid_margin=margin))
        self.action_type = action_type

    def action(self, physics: Physics) -> np.ndarray:
        """The teacher's action for the robot's current state."""
        return duty_to_action(self.action_type, self.follower.duty(physics))


__all__ = ["Teacher"]
