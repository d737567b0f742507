"""The DB18 motor model's settings, and the duty cycles the motors accept."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MotorConfig:
    """The DB18 nominal motor model: duty cycles to wheel motion."""

    max_speed: float = 0.6
    """Steady forward speed at full duty on both wheels (m/s)."""
    yaw_rate_per_duty: float = 3.75
    """Steady yaw rate per unit of (right - left) duty (rad/s)."""
    linear_time_constant: float = 0.2
    """First-order time constant of the forward speed (s)."""
    yaw_time_constant: float = 0.25
    """First-order time constant of the yaw rate (s)."""
    delay: float = 0.15
    """Command delay (s)."""


def clip_duty(left: float, right: float) -> tuple[float, float]:
    """Raw duty cycles (left, right) clipped to [-1, 1]."""
    return min(max(float(left), -1.0), 1.0), min(max(float(right), -1.0), 1.0)
