"""Policy actions to wheel duty cycles (left, right) in [-1, 1]."""

from __future__ import annotations

import numpy as np

from crllk.sim.constants import WHEEL_DISTANCE, WHEEL_RADIUS

DISCRETE_DUTIES = np.array([[0.04, 0.4], [0.4, 0.04], [0.3, 0.3]])
"""Duty cycles (left, right) of the three discrete actions: turn left, turn right, straight."""
DISCRETE_NAMES = ("left", "right", "straight")

MOTOR_CONSTANT = 27.0
"""Duckietown inverse-kinematics motor constant k (duty = wheel rate * gain / k)."""
GAIN, TRIM, LIMIT = 1.0, 0.0, 1.0


def discrete_to_duty(action: int) -> np.ndarray:
    """Duty cycles (left, right) of discrete action 0 (left), 1 (right) or 2 (straight)."""
    index = int(action)
    if not 0 <= index < len(DISCRETE_DUTIES):
        raise ValueError(f"discrete action must be 0, 1 or 2, got {action!r}")
    return DISCRETE_DUTIES[index].copy()


def velocity_steering_to_duty(action: np.ndarray) -> np.ndarray:
    """Duckietown inverse kinematics: (velocity, steering) in [-1, 1]^2 to duty (left, right).

    Wheel rates w_{r,l} = (v +- steering * b / 2) / R; duty u = w * (gain +- trim) / k, clipped
    to +-limit. So u ~= 1.165 v and the duty saturates for v >= 0.86.
    """
    velocity, steering = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    rate_right = (velocity + 0.5 * steering * WHEEL_DISTANCE) / WHEEL_RADIUS
    rate_left = (velocity - 0.5 * steering * WHEEL_DISTANCE) / WHEEL_RADIUS
    duty_right = rate_right * (GAIN + TRIM) / MOTOR_CONSTANT
    duty_left = rate_left * (GAIN - TRIM) / MOTOR_CONSTANT
    return np.clip(np.array([duty_left, duty_right]), -LIMIT, LIMIT)
