"""Lane keeping on a Duckietown map as a dm-control task.

Per control step (30 Hz by default): the action becomes wheel duty cycles; the reward is the
forward progress along the lane (m); ``cost_lane`` is |lateral offset| in decimetres (10 off
the road); ``cost_collision`` is 1 on the step that ends in a collision or a road departure.
The episode terminates (discount 0) when a footprint check point leaves the road, the chassis
touches an obstacle or the physics diverges; the 512-step time limit is a truncation.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from dm_control.rl import control
from dm_control.suite import base
from dm_env import specs

from crllk.maps import DuckietownMap, LanePose, MapObject
from crllk.maps.obstacles import ObstacleIndex, footprint_points
from crllk.sim import constants as C
from crllk.sim.motor import clip_duty
from crllk.sim.physics import Physics, check_points
from crllk.tasks.actions import discrete_duty, drive_turn_duty, velocity_steering_duty
from crllk.tasks.config import TaskConfig, load_task_config

OBSERVATIONS = ("pixels", "state")
ACTIONS = ("discrete", "continuous", "duckietown", "duty")
"""Action types (:mod:`crllk.tasks.actions`): 3 discrete duty pairs; (velocity, steering) in
[-1, 1]^2 as a forward drive and a turn; (velocity, steering) through the Duckietown inverse
kinematics, as the original; raw wheel duty cycles (left, right) in [-1, 1]."""

_CURVATURE_LOOKAHEAD = (0.15, 0.3, 0.6)
"""Distances ahead (m) at which the state observation reports lane curvature."""
OBSTACLE_RANGE = 1.5
"""Obstacles farther ahead along the lane than this (m) are not reported; an empty slot reads
(OBSTACLE_RANGE, 0, 0)."""
OBSTACLES_REPORTED = 2
"""Obstacles on the road ahead reported in the state features, nearest first."""
_BLOCKING_HALF_WIDTH = 0.1
"""An obstacle whose footprint comes this close (m) to a lane's centre line blocks the lane
(the robot is 0.075 m half-wide): encounter spawns start in front of such obstacles."""
_SPAWN_ATTEMPTS = 1000
_METRES_TO_DECIMETRES = 10.0


@dataclass(frozen=True)
class StepOutcome:
    """What one control step did; the task keeps the last one for its hooks."""

    progress: float
    lane_pose: LanePose
    cost_lane: float
    cost_collision: float
    termination: str | None
    """None, or why the episode ended: 'off_road', 'collision' or 'unstable'."""


def state_feature_names(config: TaskConfig) -> list[str]:
    """Names of the entries of the ``state`` observation, in order."""
    names = ["lateral_offset", "heading_error_sin", "heading_error_cos", "forward_speed",
             "yaw_rate"]
    names += [f"curvature_{d:g}m" for d in _CURVATURE_LOOKAHEAD]
    for k in range(1, OBSTACLES_REPORTED + 1):
        names += [f"obstacle_distance_{k}", f"obstacle_lateral_left_{k}",
                  f"obstacle_lateral_right_{k}"]
    for k in range(command_history_length(config)):
        names += [f"duty_left_t-{k}", f"duty_right_t-{k}"]
    return names


def command_history_length(config: TaskConfig) -> int:
    """Commands still in flight through the motor delay, plus the newest one."""
    return max(1, math.ceil(config.motor.delay * config.control_rate - 1e-9))


class LaneKeeping(base.Task):
    """Drive far along the lane; the costs report lane deviation and collisions."""

    def __init__(self, config: TaskConfig, observation: str = "pixels",
                 action: str = "discrete", random: np.random.RandomState | int | None = None):
        if observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {observation!r}")
        if action not in ACTIONS:
            raise ValueError(f"action must be one of {ACTIONS}, got {action!r}")
        super().__init__(random=random)
        self.config = config
        self.map: DuckietownMap = config.map
        self.observation_type = observation
        self.action_type = action
        self._history: list[tuple[float, float]] = []
        """Duty cycles (left, right) commanded, newest first."""
        self._outcome: StepOutcome | None = None
        self._previous_pose: tuple[float, float, float] | None = None
        self.obstacles = obstacle_index(self.map)
        """The map's obstacles in the lane frame (state features and encounter spawns)."""
        self.encounter = False
        """Whether this episode started in front of an obstacle (``spawn.encounters``)."""
        self.start_direction: str | None = None
        """The episode's start lane: ``"intended"`` or ``"reverse"`` loop direction of the map
        (None where the map is not one loop)."""
        self.hit_object: int | None = None
        """Index in the map's objects of the obstacle the episode ended on, if any."""
        self._blocking = [(lane, o) for lane in self.map.lanes
                          for o in self.obstacles.on_lane(lane)
                          if o.lateral_left < _BLOCKING_HALF_WIDTH
                          and o.lateral_right > -_BLOCKING_HALF_WIDTH]

    # ----- specs ------------------------------------------------------------------------
    def action_spec(self, physics: Physics):
        if self.action_type == "discrete":
            return specs.DiscreteArray(num_values=3, dtype=np.int64, name="action")
        return specs.BoundedArray((2,), np.float64, -1.0, 1.0, name="action")

    def observation_spec(self, physics: Physics) -> dict[str, specs.Array]:
        # Explicit, so the spec is available before the first reset (dm_env users ask first).
        if self.observation_type == "pixels":
            cam = self.config.camera
            main = specs.Array((cam.height, cam.width, 3), np.uint8, name="pixels")
        else:
            main = specs.Array((len(state_feature_names(self.config)),), np.float64, name="state")
        return {main.name: main,
                "cost_lane": specs.Array((), np.float64, name="cost_lane"),
                "cost_collision": specs.Array((), np.float64, name="cost_collision")}

    # ----- episode ----------------------------------------------------------------------
    def initialize_episode(self, physics: Physics) -> None:
        x, y, yaw = self._spawn_pose()
        physics.set_pose(x, y, yaw)
        physics.forward()
        self._history = [(0.0, 0.0)] * command_history_length(self.config)
        self._previous_pose = (x, y, yaw)
        pose = self.map.lane_pose(x, y, yaw)
        self._outcome = StepOutcome(0.0, pose, self._lane_cost(pose), 0.0, None)
        self.start_direction = self.map.direction_of(pose.lane)
        self.hit_object = None
        super().initialize_episode(physics)

    def _spawn_pose(self) -> tuple[float, float, float]:
        """A random start: with probability ``spawn.encounters`` (when some obstacle blocks a
        lane) in front of a blocking obstacle, otherwise on a random road tile and lane."""
        spawn = self.config.spawn
        self.encounter = bool(self._blocking) and spawn.encounters > 0 and \
            self.random.uniform() < spawn.encounters
        tiles = self.map.road_tiles
        for _ in range(_SPAWN_ATTEMPTS):
            if self.encounter:
                lane, along = self._encounter_start()
            else:
                tile = tiles[self.random.randint(len(tiles))]
                lanes = self.map.tile_lanes(tile.column, tile.row)
                lane = lanes[self.random.randint(len(lanes))]
                along = self.random.uniform(0.0, lane.length)
            offsets = spawn.encounter_lateral_offset if self.encounter else spawn.lateral_offset
            lateral = self.random.uniform(*offsets)
            x, y, heading = lane.point_at(along, lateral)
            yaw = heading + self.random.uniform(*spawn.heading_error)
            if self._spawn_is_clear(x, y, yaw):
                return x, y, yaw
        raise RuntimeError(f"{self.config.source}: spawn: no clear start pose found in "
                           f"{_SPAWN_ATTEMPTS} tries; lower spawn.obstacle_clearance")

    def _encounter_start(self) -> tuple[Any, float]:
        """(lane, along) a random ``spawn.encounter_distance`` before a blocking obstacle."""
        lane, obstacle = self._blocking[self.random.randint(len(self._blocking))]
        back = obstacle.along_start - self.random.uniform(*self.config.spawn.encounter_distance)
        while back < 0.0:
            previous = self.obstacles.previous_lane(lane)
            if previous is None:
                return lane, 0.0
            lane = previous
            back += lane.length
        return lane, back

    def _spawn_is_clear(self, x: float, y: float, yaw: float) -> bool:
        """On the road, and the footprint at least ``spawn.obstacle_clearance`` from every
        obstacle's footprint."""
        clearance = self.config.spawn.obstacle_clearance
        if any(_footprint_gap(obj, x, y, yaw) < clearance for obj in self.map.objects):
            return False
        return self.map.all_road(check_points(x, y, yaw))

    # ----- stepping ---------------------------------------------------------------------
    def before_step(self, action, physics: Physics) -> None:
        duty = self._duty(action)
        if not (math.isfinite(duty[0]) and math.isfinite(duty[1])):
            raise ValueError(f"action {action!r} is not finite")
        self._history = [duty, *self._history[:-1]]
        self._previous_pose = physics.pose()
        physics.set_wheel_duty(duty)

    def _duty(self, action) -> tuple[float, float]:
        """Wheel duty cycles (left, right) of a policy action."""
        if self.action_type == "discrete":
            return discrete_duty(action if type(action) is int else np.asarray(action).item())
        pair = np.asarray(action, dtype=np.float64).reshape(2).tolist()
        if self.action_type == "continuous":
            return drive_turn_duty(*pair)
        if self.action_type == "duckietown":
            return velocity_steering_duty(*pair)
        return clip_duty(*pair)

    def after_step(self, physics: Physics) -> None:
        x, y, yaw = physics.pose()
        pose = self.map.lane_pose(x, y, yaw)
        px, py, _ = self._previous_pose
        heading = self._outcome.lane_pose.lane.heading_at(px, py)
        progress = (x - px) * math.cos(heading) + (y - py) * math.sin(heading)
        termination = None
        if physics.diverged:
            termination, progress = "unstable", 0.0
        elif not self.map.all_road(check_points(x, y, yaw)):
            termination = "off_road"
        elif physics.touches_obstacle():
            termination = "collision"
            self.hit_object = min(range(len(self.map.objects)), key=lambda k: _footprint_gap(
                self.map.objects[k], x, y, yaw))
        off_road = termination == "off_road" or not pose.on_road
        cost_lane = self.config.off_road_lane_cost if off_road else self._lane_cost(pose)
        cost_collision = 1.0 if termination in ("off_road", "collision") else 0.0
        self._outcome = StepOutcome(progress, pose, cost_lane, cost_collision, termination)

    def _lane_cost(self, pose: LanePose) -> float:
        if not pose.on_road:
            return self.config.off_road_lane_cost
        return abs(pose.lateral) * _METRES_TO_DECIMETRES

    @property
    def command_history(self) -> list[tuple[float, float]]:
        """Wheel duties (left, right) of the last steps, newest first: those still in flight
        through the motor delay and the newest one."""
        return self._history

    @property
    def outcome(self) -> StepOutcome:
        """The last step's progress, lane pose, costs and termination reason."""
        return self._outcome

    # ----- snapshots --------------------------------------------------------------------
    def episode_state(self) -> dict[str, Any]:
        """Everything the hooks carry between steps, and the spawn generator's state, as
        plain Python values (see :meth:`load_episode_state`)."""
        name, keys, position, has_gauss, cached_gaussian = self.random.get_state(legacy=True)
        return {"history": [list(duty) for duty in self._history],
                "encounter": self.encounter,
                "start_direction": self.start_direction, "hit_object": self.hit_object,
                "previous_pose": self._previous_pose,
                "outcome": None if self._outcome is None else self._outcome_state(),
                "random": (name, keys.tolist(), position, has_gauss, cached_gaussian)}

    def load_episode_state(self, state: dict[str, Any]) -> None:
        """Restore an :meth:`episode_state`."""
        self._history = [(left, right) for left, right in state["history"]]
        self.encounter = bool(state.get("encounter", False))
        self.start_direction = state.get("start_direction")
        self.hit_object = state.get("hit_object")
        previous = state["previous_pose"]
        self._previous_pose = None if previous is None else tuple(previous)
        outcome = state["outcome"]
        self._outcome = None if outcome is None else self._outcome_from_state(outcome)
        name, keys, position, has_gauss, cached_gaussian = state["random"]
        self.random.set_state((name, np.asarray(keys, np.uint32), position, has_gauss,
                               cached_gaussian))

    def _outcome_state(self) -> dict[str, Any]:
        outcome, pose = self._outcome, self._outcome.lane_pose
        return {"progress": outcome.progress, "cost_lane": outcome.cost_lane,
                "cost_collision": outcome.cost_collision, "termination": outcome.termination,
                "lateral": pose.lateral, "heading_error": pose.heading_error,
                "on_road": pose.on_road, "along": pose.along,
                "lane": self.map.lanes.index(pose.lane)}

    def _outcome_from_state(self, state: dict[str, Any]) -> StepOutcome:
        pose = LanePose(state["lateral"], state["heading_error"], state["on_road"],
                        state["along"], self.map.lanes[state["lane"]])
        return StepOutcome(state["progress"], pose, state["cost_lane"], state["cost_collision"],
                           state["termination"])

    def get_reward(self, physics: Physics) -> float:
        return self._outcome.progress

    def get_termination(self, physics: Physics) -> float | None:
        return 0.0 if self._outcome.termination else None

    def get_observation(self, physics: Physics) -> dict[str, Any]:
        main = self.main_observation(physics)
        if self.observation_type == "state":
            main = np.array(main)
        return {self.observation_type: main,
                "cost_lane": np.float64(self._outcome.cost_lane),
                "cost_collision": np.float64(self._outcome.cost_collision)}

    def main_observation(self, physics: Physics) -> np.ndarray | list[float]:
        """The camera image (uint8 HxWx3) or the state features (a list of floats)."""
        if self.observation_type == "pixels":
            cam = self.config.camera
            return physics.render_camera(cam.height, cam.width, cam.supersample)
        return self.state_feature_list(physics)

    def obstacle_features(self, pose: LanePose) -> list[float]:
        """For each of the :data:`OBSTACLES_REPORTED` nearest obstacles on the road ahead
        along the lane: distance (m) to its footprint, and the lateral offsets of its left and
        right edges from the lane centre (m, positive right); (OBSTACLE_RANGE, 0, 0) when there
        is none."""
        found = self.obstacles.ahead(pose, OBSTACLES_REPORTED, OBSTACLE_RANGE)
        out: list[float] = []
        for k in range(OBSTACLES_REPORTED):
            if k < len(found):
                out += [found[k].distance, found[k].lateral_left, found[k].lateral_right]
            else:
                out += [OBSTACLE_RANGE, 0.0, 0.0]
        return out

    def state_features(self, physics: Physics) -> np.ndarray:
        """The ``state`` observation; see :func:`state_feature_names`."""
        return np.array(self.state_feature_list(physics))

    def state_feature_list(self, physics: Physics) -> list[float]:
        """:meth:`state_features` as a list of floats."""
        pose = self._outcome.lane_pose
        _x, _y, yaw = physics.pose()
        return [pose.lateral, math.sin(pose.heading_error), math.cos(pose.heading_error),
                physics.forward_speed(yaw), physics.yaw_rate(),
                *self.map.curvature_ahead(pose, _CURVATURE_LOOKAHEAD),
                *self.obstacle_features(pose),
                *(value for duty in self._history for value in duty)]


@functools.lru_cache(maxsize=16)
def obstacle_index(dmap: DuckietownMap) -> ObstacleIndex:
    """The obstacle index of a map, built once per map object."""
    return ObstacleIndex(dmap)


def _point_to_rectangle(px: float, py: float, cx: float, cy: float, yaw: float,
                        length: float, width: float) -> float:
    """Distance (m) from a point to a rectangle centred at (cx, cy) (0 inside)."""
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = px - cx, py - cy
    u, v = c * dx + s * dy, -s * dx + c * dy
    return math.hypot(max(abs(u) - length / 2, 0.0), max(abs(v) - width / 2, 0.0))


def _footprint_gap(obj: MapObject, x: float, y: float, yaw: float) -> float:
    """Distance (m) between the robot's footprint at axle pose (x, y, yaw) and an object's
    footprint, from points on each outline (0 when they overlap)."""
    centre_x = x - C.FOOTPRINT_CENTRE_BEHIND_AXLE * math.cos(yaw)
    centre_y = y - C.FOOTPRINT_CENTRE_BEHIND_AXLE * math.sin(yaw)
    robot = MapObject("robot", centre_x, centre_y, yaw, C.FOOTPRINT_LENGTH, C.FOOTPRINT_WIDTH,
                      0.0)
    to_object = min(_point_to_rectangle(px, py, obj.x, obj.y, obj.yaw, obj.length, obj.width)
                    for px, py in footprint_points(robot))
    to_robot = min(_point_to_rectangle(px, py, centre_x, centre_y, yaw, robot.length,
                                       robot.width) for px, py in footprint_points(obj))
    return min(to_object, to_robot)


def load(task: str | Path, *, observation: str = "pixels", action: str = "discrete",
         seed: int | np.random.RandomState | None = None,
         overrides: dict[str, Any] | None = None) -> control.Environment:
    """A ``dm_control.rl.control.Environment`` for lane keeping.

    Args:
        task: a task name (``small_loop``, ``zigzag``, ``obstacle_loop``) or the path of a task
            or Duckietown map file.
        observation: ``"pixels"`` (camera, uint8 HxWx3) or ``"state"`` (lane-relative features).
        action: ``"discrete"`` (3 duty pairs), ``"continuous"`` ((velocity, steering)) or
            ``"duty"`` (wheel duty cycles (left, right)).
        seed: seeds the spawn.
        overrides: task settings to replace, e.g. ``{"horizon": 64}``.
    """
    config = load_task_config(task, overrides)
    physics = Physics.from_map(config.map, config.motor)
    lane_task = LaneKeeping(config, observation=observation, action=action, random=seed)
    steps = config.horizon
    return control.Environment(
        physics, lane_task, time_limit=steps * config.control_timestep * (1 - 1e-9),
        control_timestep=config.control_timestep)
