"""Policy actions to wheel duty cycles (left, right) in [-1, 1].

Action types:

- ``discrete``: the original's three duty pairs (turn left, turn right, straight);
- ``continuous``: (velocity, steering) in [-1, 1]^2 as a forward drive and a turn
  (:func:`drive_turn_duty`). Velocity sets the mean duty between :data:`MIN_MEAN_DUTY` and
  :data:`MAX_MEAN_DUTY`, so the robot always moves forward and cannot stand still by
  alternating signs; steering sets the duty difference up to :data:`MAX_DUTY_DIFFERENCE`,
  which reaches the yaw rates of the discrete turns and more;
- ``duckietown``: (velocity, steering) in [-1, 1]^2 through the Duckietown inverse kinematics
  (:func:`velocity_steering_duty`), as the original code drove the robot. Through the DB18
  motor model it turns at most about 0.45 rad/s, and not at all once the velocity saturates the
  duty;
- ``duty``: raw wheel duty cycles (left, right).

The scalar functions return plain ``(left, right)`` tuples for the per-step hot path; the
``*_to_duty`` functions wrap them for array callers.
"""

from __future__ import annotations

import numpy as np

from crllk.sim.constants import WHEEL_DISTANCE, WHEEL_RADIUS

_DISCRETE = ((0.04, 0.4), (0.4, 0.04), (0.3, 0.3))
DISCRETE_DUTIES = np.array(_DISCRETE)
"""Duty cycles (left, right) of the three discrete actions: turn left, turn right, straight."""
DISCRETE_NAMES = ("left", "right", "straight")

MOTOR_CONSTANT = 27.0
"""Duckietown inverse-kinematics motor constant k (duty = wheel rate * gain / k)."""
GAIN, TRIM, LIMIT = 1.0, 0.0, 1.0

MIN_MEAN_DUTY = 0.1
"""Mean wheel duty of ``continuous`` velocity -1 (0.06 m/s steady under the DB18 model)."""
MAX_MEAN_DUTY = 0.6
"""Mean wheel duty of ``continuous`` velocity +1 (0.36 m/s steady under the DB18 model)."""
MAX_DUTY_DIFFERENCE = 0.5
"""Right minus left duty of ``continuous`` steering +1 (1.9 rad/s steady under the DB18 model;
the discrete turns differ by 0.36)."""


def _clip(value: float, limit: float = 1.0) -> float:
    """``value`` clipped to [-limit, limit] (NaN stays NaN, as with ``np.clip``)."""
    return min(max(value, -limit), limit)


def discrete_duty(action: int) -> tuple[float, float]:
    """Duty cycles (left, right) of discrete action 0 (left), 1 (right) or 2 (straight)."""
    index = int(action)
    if not 0 <= index < len(_DISCRETE):
        raise ValueError(f"discrete action must be 0, 1 or 2, got {action!r}")
    return _DISCRETE[index]


def discrete_to_duty(action: int) -> np.ndarray:
    """:func:`discrete_duty` as a new array."""
    return np.array(discrete_duty(action))


def velocity_steering_duty(velocity: float, steering: float) -> tuple[float, float]:
    """Duckietown inverse kinematics: (velocity, steering) in [-1, 1]^2 to duty (left, right).

    Wheel rates w_{r,l} = (v +- steering * b / 2) / R; duty u = w * (gain +- trim) / k, clipped
    to +-limit. So u ~= 1.165 v and the duty saturates for v >= 0.86.
    """
    velocity, steering = _clip(float(velocity)), _clip(float(steering))
    rate_right = (velocity + 0.5 * steering * WHEEL_DISTANCE) / WHEEL_RADIUS
    rate_left = (velocity - 0.5 * steering * WHEEL_DISTANCE) / WHEEL_RADIUS
    duty_right = rate_right * (GAIN + TRIM) / MOTOR_CONSTANT
    duty_left = rate_left * (GAIN - TRIM) / MOTOR_CONSTANT
    return _clip(duty_left, LIMIT), _clip(duty_right, LIMIT)


def drive_turn_duty(velocity: float, steering: float) -> tuple[float, float]:
    """``continuous`` action (velocity, steering) in [-1, 1]^2 to duty (left, right).

    Mean duty m = MIN + (velocity + 1) / 2 * (MAX - MIN), difference d = steering * MAX_DIFF
    (positive turns left), duty = (m - d / 2, m + d / 2).
    """
    velocity, steering = _clip(float(velocity)), _clip(float(steering))
    mean = MIN_MEAN_DUTY + 0.5 * (velocity + 1.0) * (MAX_MEAN_DUTY - MIN_MEAN_DUTY)
    half_difference = 0.5 * steering * MAX_DUTY_DIFFERENCE
    return mean - half_difference, mean + half_difference


def drive_turn_to_duty(action: np.ndarray) -> np.ndarray:
    """:func:`drive_turn_duty` of a (velocity, steering) pair, as an array."""
    velocity, steering = np.asarray(action, dtype=np.float64).tolist()
    return np.array(drive_turn_duty(velocity, steering))


def velocity_steering_to_duty(action: np.ndarray) -> np.ndarray:
    """:func:`velocity_steering_duty` of a (velocity, steering) pair, as an array."""
    velocity, steering = np.asarray(action, dtype=np.float64).tolist()
    return np.array(velocity_steering_duty(velocity, steering))
