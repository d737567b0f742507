"""Policy actions to wheel duty cycles (left, right) in [-1, 1].

Action types:

- ``discrete``: the original's three duty pairs (turn left, turn right, straight);
- ``continuous``: (velocity, steering) in [-1, 1]^2 as a forward drive and a turn
  (:func:`drive_turn_duty`). Velocity sets the mean duty between :data:`MIN_MEAN_DUTY` and
  :data:`MAX_MEAN_DUTY`, so the robot always moves forward and cannot stand still by
  alternating signs; steering sets the duty difference up to :data:`MAX_DUTY_DIFFERENCE`,
  which reaches the yaw rates of the discrete turns and more;
- ``stoppable``: as ``continuous``, but velocity -1 is a mean duty of 0 (up to
  :data:`MAX_MEAN_DUTY`): with steering 0 the robot stands still, with steering it turns on
  the spot; for traffic, where a robot must be able to wait;
- ``duckietown``: (velocity, steering) in [-1, 1]^2 through the Duckietown inverse kinematics
  (:func:`velocity_steering_duty`), as the original code drove the robot. Through the DB18
  motor model it turns at most about 0.45 rad/s, and not at all once the velocity saturates the
  duty;
- ``duty``: raw wheel duty cycles (left, right).

:func:`action_duty` maps any of them; every function returns a plain ``(left, right)`` tuple
(the per-step hot path).
"""

from __future__ import annotations

import numpy as np

from crllk.sim.constants import WHEEL_DISTANCE, WHEEL_RADIUS
from crllk.sim.motor import clip_duty

POLICY_ACTIONS = ("discrete", "continuous", "stoppable", "duckietown")
"""The action types a policy acts in (all but raw duties)."""
GAUSSIAN_ACTIONS = ("continuous", "stoppable", "duckietown")
"""The policy action types of two numbers in [-1, 1], drawn from a Gaussian policy."""

ACTIONS = (*POLICY_ACTIONS, "duty")
"""Action types: 3 discrete duty pairs; (velocity, steering) in [-1, 1]^2 as a drive and a
turn (never standing still, or able to), or through the Duckietown inverse kinematics, as the
original; raw wheel duty cycles (left, right) in [-1, 1]."""

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
LEAST_MEAN_DUTY = {"continuous": MIN_MEAN_DUTY, "stoppable": 0.0}
"""Mean wheel duty of velocity -1 for the drive-and-turn action types."""


def _clip(value: float, limit: float = 1.0) -> float:
    """``value`` clipped to [-limit, limit] (NaN stays NaN, as with ``np.clip``)."""
    return min(max(value, -limit), limit)


def discrete_duty(action: int) -> tuple[float, float]:
    """Duty cycles (left, right) of discrete action 0 (left), 1 (right) or 2 (straight)."""
    index = int(action)
    if not 0 <= index < len(_DISCRETE):
        raise ValueError(f"discrete action must be 0, 1 or 2, got {action!r}")
    return _DISCRETE[index]


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


def drive_turn_duty(velocity: float, steering: float,
                    least: float = MIN_MEAN_DUTY) -> tuple[float, float]:
    """``continuous`` action (velocity, steering) in [-1, 1]^2 to duty (left, right)
    (``stoppable`` with ``least`` 0).

    Mean duty m = least + (velocity + 1) / 2 * (MAX - least), difference
    d = steering * MAX_DIFF (positive turns left), duty = (m - d / 2, m + d / 2).
    """
    velocity, steering = _clip(float(velocity)), _clip(float(steering))
    mean = least + 0.5 * (velocity + 1.0) * (MAX_MEAN_DUTY - least)
    half_difference = 0.5 * steering * MAX_DUTY_DIFFERENCE
    return mean - half_difference, mean + half_difference


_TURN_DIFFERENCE = float(DISCRETE_DUTIES[0, 1] - DISCRETE_DUTIES[0, 0])
"""Right minus left duty of the discrete left turn (0.36)."""


def duty_to_action(action_type: str, duty: np.ndarray) -> np.ndarray:
    """The action of ``action_type`` nearest to wheel duties (left, right).

    - ``discrete``: the turn whose duty difference is nearest (left above half a turn's
      difference, right below minus half, straight between);
    - ``continuous`` and ``stoppable``: inverts :func:`crllk.tasks.actions.drive_turn_duty`,
      clipped to the box;
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
    if action_type in LEAST_MEAN_DUTY:
        least = LEAST_MEAN_DUTY[action_type]
        velocity = 2.0 * (mean - least) / (MAX_MEAN_DUTY - least) - 1.0
        steering = difference / MAX_DUTY_DIFFERENCE
    elif action_type == "duckietown":
        scale = WHEEL_RADIUS * MOTOR_CONSTANT / (GAIN * LIMIT)
        velocity, steering = mean * scale, difference * scale / WHEEL_DISTANCE
    elif action_type == "duty":
        velocity, steering = left, right
    else:
        raise ValueError(f"unknown action type {action_type!r}")
    return np.clip(np.array([velocity, steering]), -1.0, 1.0)


def action_duty(action_type: str, action) -> tuple[float, float]:
    """Wheel duty cycles (left, right) of a policy action of ``action_type``
    (:data:`ACTIONS`): an index for ``discrete``, a pair for the others."""
    if action_type == "discrete":
        return discrete_duty(action if type(action) is int else np.asarray(action).item())
    pair = np.asarray(action, dtype=np.float64).reshape(2).tolist()
    if action_type in LEAST_MEAN_DUTY:
        return drive_turn_duty(*pair, least=LEAST_MEAN_DUTY[action_type])
    if action_type == "duckietown":
        return velocity_steering_duty(*pair)
    if action_type == "duty":
        return clip_duty(*pair)
    raise ValueError(f"action must be one of {ACTIONS}, got {action_type!r}")
