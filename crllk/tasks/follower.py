"""A scripted lane follower with privileged access to the lane pose, optionally swerving around
obstacles and following the traffic.

It is the sanity check of the geometry and the physics, an upper-bound baseline and the teacher
of :mod:`crllk.tasks.teacher`. It predicts where the robot will be once the motor delay has passed,
measures that pose against the lane and commands a yaw rate from curvature feed-forward plus
heading and lateral feedback:

    w = v * kappa - k_heading * e_heading + k_lateral * v * (e_lateral - target)

then turns (v, w) into wheel duty cycles through the DB18 steady-state gains. The lateral target
is the lane centre, or, given the map's :class:`~crllk.maps.obstacles.ObstacleIndex`, a point
left of any obstacle that blocks the lane within ``avoid_distance`` ahead; while swerving it
steers for a heading towards that target and slows down. Given the task's movers
(:mod:`crllk.tasks.traffic`: their footprints and velocities), it follows as the vehicles do
(:mod:`crllk.tasks.following`) whatever of them is, or within ``mover_prediction`` will be, in
its path ahead, keeping its front a gap behind it: a little more than the task's headway bound
when it has traffic, else :data:`~crllk.tasks.following.FOLLOW_GAP`. So it waits for crossing
pedestrians too, and passes one that holds beside it.
:class:`FollowerPolicy` drives every simulation of a batched env with it, in the env's action type.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from crllk.maps import DuckietownMap, LanePose
from crllk.maps.obstacles import ObstacleIndex, footprint_points
from crllk.maps.routes import Route, advance
from crllk.sim.constants import FOOTPRINT_WIDTH
from crllk.sim.motor import MotorConfig
from crllk.sim.physics import Physics
from crllk.tasks.actions import duty_to_action
from crllk.tasks.config import TaskConfig
from crllk.tasks.following import FOLLOW_GAP, FRONT, LOOKAHEAD, Mover, following_speed

if TYPE_CHECKING:
    from tensordict import TensorDictBase

_MOVER_STEPS = 2
"""Steps over ``mover_prediction`` at which the movers' footprints are placed."""


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
    headway_margin: float = 0.05
    """Gap kept beyond the task's headway bound behind a mover ahead (m)."""
    path_margin: float = 0.01
    """Moving movers within the robot's half-width plus this (m) of its lateral offset are in
    its path; standing ones only within its half-width. Less than the gap a pedestrian keeps
    from a Duckiebot when it holds (:data:`crllk.tasks.traffic.YIELD_GAP`), and a holding
    pedestrian stands: one holding beside the robot, or diagonally ahead of its front corner,
    lets it pass (else each would wait for the other)."""
    mover_prediction: float = 1.0
    """Where a mover goes at its velocity within this time (s) counts as where it is."""


class LaneFollower:
    """Drives a robot along its lane from the true pose (privileged)."""

    def __init__(self, dmap: DuckietownMap, motor: MotorConfig,
                 gains: FollowerGains | None = None,
                 obstacles: ObstacleIndex | None = None, headway: float | None = None) -> None:
        self.map = dmap
        self.motor = motor
        self.gains = gains or FollowerGains()
        self.obstacles = obstacles
        """Given, the follower swerves around obstacles that block its lane."""
        self.keep = (FOLLOW_GAP if headway is None
                     else max(FOLLOW_GAP, headway + self.gains.headway_margin))
        """Gap (m) kept from the robot's front to a mover ahead: ``headway_margin`` more than
        the task's headway bound ``headway`` (m), or :data:`FOLLOW_GAP` without one."""

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

    def mover_speed_limit(self, pose: LanePose, movers: Sequence[Mover]) -> float | None:
        """Highest speed (m/s) that keeps :attr:`keep` from the front of a robot at ``pose`` to
        the nearest footprint of ``movers``, now or ``mover_prediction`` ahead at its velocity,
        in its path (``path_margin``) ahead of that front along the lanes; None when none is
        within :data:`LOOKAHEAD`. What is beside the robot, behind its front, it passes."""
        route = Route(self.map, *advance(self.map, pose.lane, pose.along, FRONT), LOOKAHEAD)
        times = [self.gains.mover_prediction * k / _MOVER_STEPS for k in range(_MOVER_STEPS + 1)]
        ahead = []
        for box, (vx, vy) in movers:
            reach = FOOTPRINT_WIDTH / 2 + (self.gains.path_margin if vx or vy else 0.0)
            ahead += [p.distance for x, y in footprint_points(box, 3) for t in times
                      if (p := route.project(x + vx * t, y + vy * t)) is not None
                      and abs(p.lateral - pose.lateral) <= reach]
        return following_speed(min(ahead), self.keep) if ahead else None

    def duty(self, physics: Physics, movers: Sequence[Mover] = ()) -> np.ndarray:
        """Wheel duty cycles (left, right) for the robot's current state, following whatever
        of ``movers`` is in its path ahead."""
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
        if movers and (limit := self.mover_speed_limit(pose, movers)) is not None:
            target_speed = min(target_speed, limit)
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


def task_headway(config: TaskConfig) -> float | None:
    """The headway bound (m) of a task that constrains the headway, else None: what the
    follower keeps a little more than behind a mover ahead."""
    if config.traffic is None or not any(c.signal == "headway" for c in config.constraints):
        return None
    return config.traffic.headway


class FollowerPolicy:
    """The scripted lane follower (:class:`crllk.tasks.follower.LaneFollower`) as a policy for a
    batched env: writes every sub-environment's wheel duties, or with another action type the
    action nearest to them (:func:`crllk.tasks.actions.duty_to_action`, as the teacher answers);
    with ``avoid_obstacles`` it swerves around obstacles, ``margin`` (m) clear of them; with
    ``avoid_movers`` it follows the task's movers in its path."""

    def __init__(self, env: Any, *, avoid_obstacles: bool = False, avoid_movers: bool = True,
                 margin: float = FollowerGains.avoid_margin) -> None:
        self.env = env
        self.action_type = getattr(env, "action_type", "duty")
        self.avoid_movers = avoid_movers
        obstacles = ObstacleIndex(env.config.map) if avoid_obstacles else None
        self.follower = LaneFollower(env.config.map, env.config.motor, obstacles=obstacles,
                                     gains=FollowerGains(avoid_margin=margin),
                                     headway=task_headway(env.config))

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        import torch  # the follower's geometry needs no torch; only this batched policy does

        duties = [self.follower.duty(physics, task.movers if self.avoid_movers else ())
                  for physics, task in zip(self.env.physics, self.env.tasks, strict=True)]
        if self.action_type == "duty":
            td.set("action", torch.as_tensor(np.stack(duties), dtype=torch.float32))
        else:
            actions = np.stack([duty_to_action(self.action_type, d) for d in duties])
            td.set("action", torch.as_tensor(actions).to(self.env.action_spec.dtype))
        return td
