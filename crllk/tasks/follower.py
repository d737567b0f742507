"""A scripted lane follower with privileged access to the lane pose, optionally swerving around
obstacles.

It is the sanity check of the geometry and the physics, an upper-bound baseline and the teacher
of :mod:`crllk.tasks.teacher`. It predicts where the robot will be once the motor delay has passed,
measures that pose against the lane and commands a yaw rate from curvature feed-forward plus
heading and lateral feedback:

    w = v * kappa - k_heading * e_heading + k_lateral * v * (e_lateral - target)

then turns (v, w) into wheel duty cycles through the DB18 steady-state gains. The lateral target
is the lane centre, or, given the map's :class:`~crllk.maps.obstacles.ObstacleIndex`, a point
left of any obstacle that blocks the lane within ``avoid_distance`` ahead; while swerving it
steers for a heading towards that target and slows down.
:class:`FollowerPolicy` drives every simulation of a batched env with it, in the env's action type.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from crllk.maps import DuckietownMap, LanePose
from crllk.maps.obstacles import ObstacleIndex
from crllk.sim.constants import FOOTPRINT_WIDTH
from crllk.sim.motor import MotorConfig
from crllk.sim.physics import Physics
from crllk.tasks.actions import duty_to_action

if TYPE_CHECKING:
    from tensordict import TensorDictBase


@dataclass(frozen=True)
class FollowerGains:
    """Gains and speeds of the lane follower."""

    cruise_speed: float = 0.25
    """Forward speed on straights (m/s)."""
    max_lateral_acceleration: float = 0.18
    """Speed in curves is limited to sqrt(a / |kappa|) (m/s^2)."""
    heading_gain: float = 5.0
    """Yaw rate per radian of heading error (1/s)."""
    lateral_gain: float = 25.0
    """Yaw rate per metre of lateral offset per m/s of speed (1/m^2)."""
    prediction_time: float = 0.1
    """Look this far beyond the motor delay when predicting the pose (s)."""
    avoid_distance: float = 0.5
    """Swerve around obstacles that block the lane within this distance ahead (m)."""
    avoid_margin: float = 0.07
    """Gap kept between the robot's side and an obstacle's edge while passing it (m)."""
    avoid_speed: float = 0.15
    """Forward speed while swerving (m/s)."""
    swerve_gain: float = 6.0
    """Heading (rad) aimed for per metre of distance from the swerve target."""
    max_swerve_heading: float = 0.8
    """Largest heading error aimed for while swerving (rad)."""


class LaneFollower:
    """Drives a robot along its lane from the true pose (privileged)."""

    def __init__(self, dmap: DuckietownMap, motor: MotorConfig,
                 gains: FollowerGains | None = None,
                 obstacles: ObstacleIndex | None = None) -> None:
        self.map = dmap
        self.motor = motor
        self.gains = gains or FollowerGains()
        self.obstacles = obstacles
        """Given, the follower swerves around obstacles that block its lane."""

    def swerve_target(self, pose: LanePose) -> float:
        """Lateral offset (m, positive right) to pass every obstacle that blocks the lane
        within ``avoid_distance`` on its left; 0 (the lane centre) when none does."""
        if self.obstacles is None:
            return 0.0
        g = self.gains
        reach = FOOTPRINT_WIDTH / 2 + g.avoid_margin
        target = 0.0
        for obstacle in self.obstacles.ahead(pose, 2, g.avoid_distance):
            if obstacle.lateral_left < reach and obstacle.lateral_right > -reach:
                target = min(target, obstacle.lateral_left - reach)
        return target

    def duty(self, physics: Physics) -> np.ndarray:
        """Wheel duty cycles (left, right) for the robot's current state."""
        g = self.gains
        x, y, yaw = physics.pose()
        speed, yaw_rate = physics.forward_speed(), physics.yaw_rate()
        horizon = self.motor.delay + g.prediction_time
        x, y, yaw = _predict(x, y, yaw, speed, yaw_rate, horizon)
        pose = self.map.lane_pose(x, y, yaw)
        curvature = max((abs(k) for k in self.map.curvature_ahead(pose, (0.0, 0.1))),
                        default=0.0)
        target_speed = g.cruise_speed
        if curvature > 0:
            target_speed = min(target_speed, math.sqrt(g.max_lateral_acceleration / curvature))
        lane_curvature = self.map.curvature_ahead(pose, (0.0,))[0]
        target = self.swerve_target(pose)
        if target < 0.0:
            target_speed = min(target_speed, g.avoid_speed)
            aim = min(max(g.swerve_gain * (pose.lateral - target), -g.max_swerve_heading),
                      g.max_swerve_heading)
            yaw_rate_command = (target_speed * lane_curvature
                                - g.heading_gain * (pose.heading_error - aim))
        else:
            yaw_rate_command = (target_speed * lane_curvature
                                - g.heading_gain * pose.heading_error
                                + g.lateral_gain * target_speed * pose.lateral)
        mean = target_speed / self.motor.max_speed
        difference = yaw_rate_command / self.motor.yaw_rate_per_duty
        return np.clip([mean - difference / 2, mean + difference / 2], -1.0, 1.0)


def _predict(x: float, y: float, yaw: float, speed: float, yaw_rate: float,
             horizon: float) -> tuple[float, float, float]:
    """Pose after ``horizon`` s at constant speed and yaw rate (unicycle arc)."""
    new_yaw = yaw + yaw_rate * horizon
    if abs(yaw_rate) < 1e-6:
        return x + speed * horizon * math.cos(yaw), y + speed * horizon * math.sin(yaw), new_yaw
    radius = speed / yaw_rate
    return (x + radius * (math.sin(new_yaw) - math.sin(yaw)),
            y - radius * (math.cos(new_yaw) - math.cos(yaw)), new_yaw)


class FollowerPolicy:
    """The scripted lane follower (:class:`crllk.tasks.follower.LaneFollower`) as a policy for a
    batched env: writes every sub-environment's wheel duties, or with another action type the
    action nearest to them (:func:`crllk.tasks.actions.duty_to_action`, as the teacher answers);
    with ``avoid_obstacles`` it swerves around obstacles, ``margin`` (m) clear of them."""

    def __init__(self, env: Any, *, avoid_obstacles: bool = False,
                 margin: float = FollowerGains.avoid_margin) -> None:
        self.env = env
        self.action_type = getattr(env, "action_type", "duty")
        obstacles = ObstacleIndex(env.config.map) if avoid_obstacles else None
        self.follower = LaneFollower(env.config.map, env.config.motor, obstacles=obstacles,
                                     gains=FollowerGains(avoid_margin=margin))

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        import torch  # the follower's geometry needs no torch; only this batched policy does

        duties = [self.follower.duty(physics) for physics in self.env.physics]
        if self.action_type == "duty":
            td.set("action", torch.as_tensor(np.stack(duties), dtype=torch.float32))
        else:
            actions = np.stack([duty_to_action(self.action_type, d) for d in duties])
            td.set("action", torch.as_tensor(actions).to(self.env.action_spec.dtype))
        return td
