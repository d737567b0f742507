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
from crllk.sim.constants import WHEEL_DISTANCE, WHEEL_RADIUS
from crllk.sim.physics import Physics
from crllk.tasks.actions import (
    DISCRETE_DUTIES,
    GAIN,
    LIMIT,
    MAX_DUTY_DIFFERENCE,
    MAX_MEAN_DUTY,
    MIN_MEAN_DUTY,
    MOTOR_CONSTANT,
)
from crllk.tasks.config import TaskConfig
from crllk.tasks.follower import LaneFollower

_TURN_DIFFERENCE = float(DISCRETE_DUTIES[0, 1] - DISCRETE_DUTIES[0, 0])
"""Right minus left duty of the discrete left turn (0.36)."""


def duty_to_action(action_type: str, duty: np.ndarray) -> np.ndarray:
    """The action of ``action_type`` nearest to wheel duties (left, right).

    - ``discrete``: the turn whose duty difference is nearest (left above half a turn's
      difference, right below minus half, straight between);
    - ``continuous``: inverts :func:`crllk.tasks.actions.drive_turn_duty`, clipped to the box;
    - ``duckietown``: inverts the Duckietown inverse kinematics, clipped to the box;
    - ``duty``: the duties.
    """
    left, right = float(duty[0]), float(duty[1])
    difference, mean = right - left, 0.5 * (left + right)
    if action_type == "discrete":
        if difference > _TURN_DIFFERENCE / 2:
            return np.array(0)
        if difference < -_TURN_DIFFERENCE / 2:
            return np.array(1)
        return np.array(2)
    if action_type == "continuous":
        velocity = 2.0 * (mean - MIN_MEAN_DUTY) / (MAX_MEAN_DUTY - MIN_MEAN_DUTY) - 1.0
        steering = difference / MAX_DUTY_DIFFERENCE
    elif action_type == "duckietown":
        scale = WHEEL_RADIUS * MOTOR_CONSTANT / (GAIN * LIMIT)
        velocity, steering = mean * scale, difference * scale / WHEEL_DISTANCE
    elif action_type == "duty":
        velocity, steering = left, right
    else:
        raise ValueError(f"unknown action type {action_type!r}")
    return np.clip(np.array([velocity, steering]), -1.0, 1.0)


class Teacher:
    """The obstacle-avoiding follower of one task, answering in an action type."""

    def __init__(self, config: TaskConfig, obstacles: ObstacleIndex, action_type: str):
        self.follower = LaneFollower(config.map, config.motor, obstacles=obstacles)
        self.action_type = action_type

    def action(self, physics: Physics) -> np.ndarray:
        """The teacher's action for the robot's current state."""
        return duty_to_action(self.action_type, self.follower.duty(physics))


__all__ = ["Teacher", "duty_to_action"]
