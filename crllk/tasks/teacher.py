"""The privileged teacher: the scripted follower that swerves around obstacles and follows the
movers ahead in its lane, as actions of the policy's own action type.

Training can add an imitation term that pulls the policy towards the teacher's action on every
state the policy itself visits (:func:`crllk.rl.loss.imitation_loss`), so the policy starts from a
driver that passes obstacles and Lagrangian PPO refines it. The teacher reads the true pose and
the map; the policy never does.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from crllk.maps.obstacles import ObstacleIndex
from crllk.sim.physics import Physics
from crllk.tasks.actions import duty_to_action
from crllk.tasks.config import TaskConfig
from crllk.tasks.follower import FollowerGains, LaneFollower, task_headway
from crllk.tasks.following import Mover


class Teacher:
    """The obstacle-avoiding, mover-following follower of one task, answering in an action
    type."""

    def __init__(self, config: TaskConfig, obstacles: ObstacleIndex, action_type: str,
                 margin: float = FollowerGains.avoid_margin):
        """``margin``: the gap (m) kept between the robot's side and an obstacle's edge while
        passing it."""
        self.follower = LaneFollower(config.map, config.motor, obstacles=obstacles,
                                     gains=FollowerGains(avoid_margin=margin),
                                     headway=task_headway(config))
        self.action_type = action_type

    def action(self, physics: Physics, movers: Sequence[Mover] = ()) -> np.ndarray:
        """The teacher's action for the robot's current state, among the task's ``movers``
        (:attr:`~crllk.tasks.lane_keeping.LaneKeeping.movers`)."""
        return duty_to_action(self.action_type, self.follower.duty(physics, movers))


__all__ = ["Teacher"]
