"""Lane keeping on a Duckietown map as a dm-control task.

Per control step (30 Hz by default): the action becomes wheel duty cycles; the reward is the
forward progress along the lane (m); the task computes every per-step signal of
:data:`crllk.tasks.constraints.SIGNALS` (lane deviation in decimetres, 10 off the road; 1 on the
step that ends in a collision or a road departure; 1 on a step that crosses a lane line outside
intersections) and reports ``cost_<name>`` for each constraint the task declares
(``constraints``). The episode terminates (discount 0) when a footprint check point leaves the
road (also past a dead end of an open road), the chassis touches an obstacle or a moving agent
(:mod:`crllk.tasks.traffic`, moved before each step) or the physics diverges; the 512-step
time limit is a truncation.

It stays one file, over 350 lines: the task is one dm-control ``Task`` whose spawn, step, cost
and observation hooks all read and write the same episode state (:class:`EpisodeState`), and it
reads top to bottom as a task of dm_control's suite does.
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from dm_control.rl import control
from dm_env import specs

from crllk.maps import DuckietownMap, Lane, LanePose, MapObject
from crllk.maps.lanes import LANE_OFFSET
from crllk.maps.markings import lane_edges, white_lateral
from crllk.maps.obstacles import LaneObstacle, ObstacleIndex, footprint_points
from crllk.sim import constants as C
from crllk.sim.camera_effects import FrameEffects, add_noise, compress
from crllk.sim.physics import Physics, check_points
from crllk.sim.variation import SceneVariation
from crllk.tasks.actions import ACTIONS, action_duty
from crllk.tasks.config import TaskConfig, load_task_config
from crllk.tasks.constraints import Constraint
from crllk.tasks.following import Mover
from crllk.tasks.frames import robot_camera_image
from crllk.tasks.randomization import distractor_count, draw_variation, max_delay
from crllk.tasks.traffic import Traffic

OBSERVATIONS = ("pixels", "state")

_CURVATURE_LOOKAHEAD = (0.15, 0.3, 0.6)
"""Distances ahead (m) at which the state observation reports lane curvature."""
OBSTACLE_RANGE = 1.5
"""Obstacles farther ahead along the lane than this (m) are not reported; an empty slot reads
(OBSTACLE_RANGE, 0, 0)."""
OBSTACLES_REPORTED = 2
"""Obstacles on the road ahead reported in the state features, nearest first."""
MOVER_RANGE = 1.5
"""Movers farther ahead along the lane than this (m) are not reported; an empty slot reads
(MOVER_RANGE, 0, 0, 0)."""
MOVERS_REPORTED = 2
"""Movers reaching into the robot's lane ahead reported in the state features of a task with
traffic, nearest first."""
_BLOCKING_HALF_WIDTH = 0.1
"""An obstacle whose footprint comes this close (m) to a lane's centre line blocks the lane
(the robot is 0.075 m half-wide): encounter spawns start in front of such obstacles."""
_SPAWN_ATTEMPTS = 1000
_METRES_TO_DECIMETRES = 10.0


@dataclass(frozen=True)
class StepOutcome:
    """What one control step did."""

    progress: float
    """Forward progress along the lane (m)."""
    lateral: float
    heading_error: float
    on_road: bool
    along: float
    lane: int
    """The lane pose after the step (:class:`~crllk.maps.LanePose`, its lane as an index into
    the map's lanes)."""
    signals: dict[str, float]
    """Every per-step signal of :data:`~crllk.tasks.constraints.SIGNALS`, by name."""
    termination: str | None
    """None, or why the episode ended: 'off_road', 'collision' or 'unstable'."""
    in_lane: bool = True
    """On the road with the robot's centre between its lane's edges (the inner edges of the
    yellow and the white tape): the community's "in the drivable lane"."""

    def cost(self, constraint: Constraint) -> float:
        """The step's cost of ``constraint``."""
        return self.signals[constraint.signal]


@dataclass
class EpisodeState:
    """Everything the task carries from one step of an episode to the next. Snapshots save
    and restore it whole (:meth:`LaneKeeping.episode_state`), so a field added here is part of
    every checkpoint without further code; fields hold plain values only."""

    history: list[tuple[float, float]] = field(default_factory=list)
    """Duty cycles (left, right) commanded, newest first."""
    previous_pose: tuple[float, float, float] | None = None
    """The axle pose (x, y, yaw) before the current step."""
    outcome: StepOutcome | None = None
    """The last step's (or the reset's) outcome."""
    encounter: bool = False
    """Whether this episode started in front of an obstacle (``spawn.encounters``)."""
    start_direction: str | None = None
    """The episode's start lane: ``"intended"`` or ``"reverse"`` loop direction of the map
    (None where the map is not one loop)."""
    variation: dict[str, Any] | None = None
    """The episode's domain randomisation draws (:meth:`SceneVariation.as_dict`), or None."""
    steps: int = 0
    """Control steps taken in the episode (the frame counter of the sensor noise)."""
    hit_object: int | None = None
    """Index in the map's objects of the obstacle the episode ended on, if any."""
    hit_mover: int | None = None
    """Index of the moving agent the episode ended on (vehicles, then pedestrians), if any."""
    traffic: dict[str, Any] | None = None
    """The movers' state (:meth:`crllk.tasks.traffic.Traffic.reset`), None without traffic."""


def state_feature_names(config: TaskConfig) -> list[str]:
    """Names of the entries of the ``state`` observation, in order; with traffic they end in
    the movers' slots (:meth:`LaneKeeping.mover_features`)."""
    names = ["lateral_offset", "heading_error_sin", "heading_error_cos", "forward_speed",
             "yaw_rate"]
    names += [f"curvature_{d:g}m" for d in _CURVATURE_LOOKAHEAD]
    for k in range(1, OBSTACLES_REPORTED + 1):
        names += [f"obstacle_distance_{k}", f"obstacle_lateral_left_{k}",
                  f"obstacle_lateral_right_{k}"]
    for k in range(command_history_length(config)):
        names += [f"duty_left_t-{k}", f"duty_right_t-{k}"]
    if config.traffic is not None:
        for k in range(1, MOVERS_REPORTED + 1):
            names += [f"mover_distance_{k}", f"mover_lateral_left_{k}",
                      f"mover_lateral_right_{k}", f"mover_speed_{k}"]
    return names


def command_history_length(config: TaskConfig) -> int:
    """Commands still in flight through the motor delay, plus the newest one."""
    return max(1, math.ceil(config.motor.delay * config.control_rate - 1e-9))


def encounter_weights(blocking: list[tuple[Lane, LaneObstacle]],
                      curve_weight: float) -> np.ndarray | None:
    """Probabilities of the encounter starts before ``blocking`` (lane, obstacle) pairs: those
    on a lane that turns ``curve_weight`` times likelier than those on a straight lane; None
    when all are alike (the starts then draw the obstacle as they always have)."""
    weights = np.array([curve_weight if lane.turn else 1.0 for lane, _ in blocking])
    if not blocking or np.all(weights == weights[0]):
        return None
    return weights / weights.sum()


class LaneKeeping(control.Task):
    """Drive far along the lane; the costs report lane deviation and collisions.

    A ``dm_control.rl.control.Task`` with the Control Suite's conventions (``random``, a
    ``RandomState`` drawing everything random of an episode), without importing the suite,
    whose domains take about 0.6 s to import in every process."""

    def __init__(self, config: TaskConfig, observation: str = "pixels",
                 action: str = "discrete", random: np.random.RandomState | int | None = None):
        if observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {observation!r}")
        if action not in ACTIONS:
            raise ValueError(f"action must be one of {ACTIONS}, got {action!r}")
        self.random = (random if isinstance(random, np.random.RandomState)
                       else np.random.RandomState(random))
        self.config = config
        self.map: DuckietownMap = config.map
        self.observation_type = observation
        self.action_type = action
        self.episode = EpisodeState()
        """The running episode's state."""
        self.variation: SceneVariation | None = None
        """The running episode's domain randomisation (``episode.variation`` as an object)."""
        self.obstacles = obstacle_index(self.map)
        """The map's obstacles in the lane frame (state features and encounter spawns)."""
        self._colliding = tuple(obj for obj in self.map.objects if obj.collidable)
        self._offroad_cells = self.map.offroad_cells()
        """Cells where randomised episodes scatter their distractor patches."""
        """The map's objects the robot collides with."""
        self._lane_lines = (-LANE_OFFSET, white_lateral(self.map.tile_size))
        self._lane_edges = lane_edges(self.map.tile_size)
        """Lateral offsets (m) of the yellow centre line and the white edge line."""
        self.traffic = (None if config.traffic is None
                        else Traffic(config.traffic, self.map, config.control_timestep))
        """The task's moving agents (None: none)."""
        self._blocking = [(lane, o) for lane in self.map.lanes
                          for o in self.obstacles.on_lane(lane)
                          if o.lateral_left < _BLOCKING_HALF_WIDTH
                          and o.lateral_right > -_BLOCKING_HALF_WIDTH]
        self._encounter_weights = encounter_weights(self._blocking,
                                                    config.spawn.encounter_curve_weight)
        """Probability of an encounter start before each blocking obstacle (None: alike)."""

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
        costs = {c.cost_key: specs.Array((), np.float64, name=c.cost_key)
                 for c in self.config.constraints}
        return {main.name: main, **costs}

    # ----- episode ----------------------------------------------------------------------
    def initialize_episode(self, physics: Physics) -> None:
        encounter = self._draw_encounter()
        x, y, yaw = self._spawn_pose(encounter)
        if self.config.randomize is not None:
            self.variation = draw_variation(self.config.randomize, self.config.motor,
                                            len(self.map.objects), self.random,
                                            self._offroad_cells, self.map.tile_size)
            physics.set_variation(self.variation)
        physics.set_pose(x, y, yaw)
        pose = self.map.lane_pose(x, y, yaw)
        traffic = None
        if self.traffic is not None:
            traffic = self.traffic.reset(self.random, pose.lane, pose.along)
            physics.set_mover_poses(self.traffic.poses(traffic))
        physics.forward()
        signals = {"lane_deviation": self._lane_cost(pose), "collision": 0.0,
                   "lane_crossing": 0.0, "headway": self._headway(traffic, pose)}
        self.episode = EpisodeState(
            history=[(0.0, 0.0)] * command_history_length(self.config),
            previous_pose=(x, y, yaw), outcome=self._outcome(0.0, pose, signals, None),
            encounter=encounter, start_direction=self.map.direction_of(pose.lane),
            variation=None if self.variation is None else self.variation.as_dict(),
            traffic=traffic)
        self.after_step(physics)  # the spawn's outcome; frames count from 1 (per-frame noise)

    def _draw_encounter(self) -> bool:
        """Whether the episode starts in front of an obstacle: with probability
        ``spawn.encounters``, when some obstacle blocks a lane."""
        spawn = self.config.spawn
        return bool(self._blocking) and spawn.encounters > 0 and \
            self.random.uniform() < spawn.encounters

    def _spawn_pose(self, encounter: bool) -> tuple[float, float, float]:
        """A random start: in front of a blocking obstacle (``encounter``), otherwise on a
        random road tile and lane."""
        spawn = self.config.spawn
        tiles = self.map.road_tiles
        for _ in range(_SPAWN_ATTEMPTS):
            if encounter:
                lane, along = self._encounter_start()
            else:
                tile = tiles[self.random.randint(len(tiles))]
                lanes = self.map.tile_lanes(tile.column, tile.row)
                lane = lanes[self.random.randint(len(lanes))]
                along = self.random.uniform(0.0, lane.length)
            offsets = spawn.encounter_lateral_offset if encounter else spawn.lateral_offset
            lateral = self.random.uniform(*offsets)
            x, y, heading = lane.point_at(along, lateral)
            yaw = heading + self.random.uniform(*spawn.heading_error)
            if self._spawn_is_clear(x, y, yaw):
                return x, y, yaw
        raise RuntimeError(f"{self.config.source}: spawn: no clear start pose found in "
                           f"{_SPAWN_ATTEMPTS} tries; lower spawn.obstacle_clearance")

    def _encounter_obstacle(self) -> tuple[Lane, LaneObstacle]:
        """A blocking (lane, obstacle) drawn for an encounter start, by its weight."""
        weights = self._encounter_weights
        if weights is None:
            return self._blocking[self.random.randint(len(self._blocking))]
        return self._blocking[self.random.choice(len(self._blocking), p=weights)]

    def _encounter_start(self) -> tuple[Any, float]:
        """(lane, along) a random ``spawn.encounter_distance`` before a blocking obstacle."""
        lane, obstacle = self._encounter_obstacle()
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
        footprint of an object the robot collides with."""
        clearance = self.config.spawn.obstacle_clearance
        if any(_footprint_gap(obj, x, y, yaw) < clearance for obj in self._colliding):
            return False
        return self.map.all_road(check_points(x, y, yaw))

    # ----- stepping ---------------------------------------------------------------------
    def before_step(self, action, physics: Physics) -> None:
        duty = action_duty(self.action_type, action)
        if not (math.isfinite(duty[0]) and math.isfinite(duty[1])):
            raise ValueError(f"action {action!r} is not finite")
        self.episode.history = [duty, *self.episode.history[:-1]]
        self.episode.previous_pose = physics.pose()
        physics.set_wheel_duty(duty)
        if self.traffic is not None:
            physics.set_mover_poses(self.traffic.step(self.episode.traffic,
                                                      self.episode.previous_pose))

    def after_step(self, physics: Physics) -> None:
        self.episode.steps += 1
        x, y, yaw = physics.pose()
        pose = self.map.lane_pose(x, y, yaw)
        px, py, _ = self.episode.previous_pose
        previous = self.episode.outcome
        heading = self.map.lanes[previous.lane].heading_at(px, py)
        progress = (x - px) * math.cos(heading) + (y - py) * math.sin(heading)
        termination = None
        if physics.diverged:
            termination, progress = "unstable", 0.0
        elif not self.map.all_road(check_points(x, y, yaw)):
            termination = "off_road"
        elif physics.touches_obstacle():
            termination = "collision"
            self.episode.hit_object = min(
                (k for k, obj in enumerate(self.map.objects) if obj.collidable),
                key=lambda k: _footprint_gap(self.map.objects[k], x, y, yaw))
        elif self.traffic is not None and (mover := physics.touched_mover()) is not None:
            termination = "collision"
            self.episode.hit_mover = mover
        off_road = termination == "off_road" or not pose.on_road
        signals = {
            "lane_deviation": self.config.off_road_lane_cost if off_road
            else self._lane_cost(pose),
            "collision": 1.0 if termination in ("off_road", "collision") else 0.0,
            "lane_crossing": 1.0 if self._crosses_line(previous, pose) else 0.0,
            "headway": self._headway(self.episode.traffic, pose),
        }
        self.episode.outcome = self._outcome(progress, pose, signals, termination)

    def _outcome(self, progress: float, pose: LanePose, signals: dict[str, float],
                 termination: str | None) -> StepOutcome:
        left, right = self._lane_edges
        in_lane = (pose.on_road and termination != "off_road"
                   and left <= pose.lateral <= right)
        return StepOutcome(progress, pose.lateral, pose.heading_error, pose.on_road, pose.along,
                           self._lane_index[id(pose.lane)], signals, termination, in_lane)

    def _crosses_line(self, before: StepOutcome, after: LanePose) -> bool:
        """Whether the robot's centre went from one side of a lane line to the other (both
        poses on the road and off intersections, where no lane lines are painted)."""
        if not (before.on_road and after.on_road):
            return False
        if any(self.map.tile(lane.column, lane.row).intersection
               for lane in (self.map.lanes[before.lane], after.lane)):
            return False
        return any((before.lateral - line) * (after.lateral - line) < 0.0
                   for line in self._lane_lines)

    def _headway(self, traffic: dict[str, Any] | None, pose: LanePose) -> float:
        """The headway signal: 1 when the gap to the vehicle ahead in the robot's lane is
        below ``traffic.headway`` (m), else 0 (always 0 without traffic)."""
        if traffic is None:
            return 0.0
        return 1.0 if self.traffic.within_headway(traffic, pose.lane, pose.along) else 0.0

    def _lane_cost(self, pose: LanePose) -> float:
        if not pose.on_road:
            return self.config.off_road_lane_cost
        return abs(pose.lateral) * _METRES_TO_DECIMETRES

    @functools.cached_property
    def _lane_index(self) -> dict[int, int]:
        return {id(lane): k for k, lane in enumerate(self.map.lanes)}

    @property
    def command_history(self) -> list[tuple[float, float]]:
        """Wheel duties (left, right) of the last steps, newest first: those still in flight
        through the motor delay and the newest one."""
        return self.episode.history

    @property
    def outcome(self) -> StepOutcome:
        """The last step's progress, lane pose, signals and termination reason."""
        return self.episode.outcome

    @property
    def lane_pose(self) -> LanePose:
        """The lane pose after the last step."""
        o = self.episode.outcome
        return LanePose(o.lateral, o.heading_error, o.on_road, o.along, self.map.lanes[o.lane])

    @property
    def encounter(self) -> bool:
        return self.episode.encounter

    @property
    def start_direction(self) -> str | None:
        return self.episode.start_direction

    @property
    def hit_object(self) -> int | None:
        return self.episode.hit_object

    @property
    def hit_mover(self) -> int | None:
        return self.episode.hit_mover

    @property
    def mover_boxes(self) -> list[MapObject]:
        """The moving agents' footprint boxes now (none without traffic)."""
        if self.traffic is None:
            return []
        return self.traffic.boxes(self.episode.traffic)

    @property
    def movers(self) -> list[Mover]:
        """The moving agents' footprint boxes now and velocities over the last step (none
        without traffic)."""
        if self.traffic is None:
            return []
        return self.traffic.movers(self.episode.traffic)

    # ----- snapshots --------------------------------------------------------------------
    def episode_state(self) -> dict[str, Any]:
        """The whole :class:`EpisodeState` and the spawn generator's state, as plain Python
        values (see :meth:`load_episode_state`)."""
        name, keys, position, has_gauss, cached_gaussian = self.random.get_state(legacy=True)
        return {"episode": asdict(self.episode),
                "random": (name, keys.tolist(), position, has_gauss, cached_gaussian)}

    def load_episode_state(self, state: dict[str, Any], physics: Physics | None = None) -> None:
        """Restore an :meth:`episode_state`; with ``physics``, also the episode's domain
        randomisation there (before its MuJoCo state is restored)."""
        episode = dict(state["episode"])
        outcome = episode["outcome"]
        episode["outcome"] = None if outcome is None else StepOutcome(**outcome)
        episode["history"] = [tuple(duty) for duty in episode["history"]]
        if episode["previous_pose"] is not None:
            episode["previous_pose"] = tuple(episode["previous_pose"])
        episode["traffic"] = copy.deepcopy(episode.get("traffic"))  # stepped in place
        self.episode = EpisodeState(**episode)
        variation = episode.get("variation")
        self.variation = None if variation is None else SceneVariation.from_dict(variation)
        if physics is not None and (self.variation is not None or physics.variation is not None):
            physics.set_variation(self.variation)
        name, keys, position, has_gauss, cached_gaussian = state["random"]
        self.random.set_state((name, np.asarray(keys, np.uint32), position, has_gauss,
                               cached_gaussian))

    def get_reward(self, physics: Physics) -> float:
        return self.episode.outcome.progress

    def get_termination(self, physics: Physics) -> float | None:
        return 0.0 if self.episode.outcome.termination else None

    def get_observation(self, physics: Physics) -> dict[str, Any]:
        main = self.main_observation(physics)
        if self.observation_type == "state":
            main = np.array(main)
        outcome = self.episode.outcome
        return {self.observation_type: main,
                **{c.cost_key: np.float64(outcome.cost(c)) for c in self.config.constraints}}

    def main_observation(self, physics: Physics) -> np.ndarray | list[float]:
        """The camera image (uint8 HxWx3) or the state features (a list of floats)."""
        if self.observation_type == "pixels":
            image = self.camera_image(physics)
            return image if self.variation is None else self._camera_effects(image)
        return self.state_feature_list(physics)

    def camera_image(self, physics: Physics) -> np.ndarray:
        """The camera image (uint8 HxWx3) before the episode's camera effects."""
        cam = self.config.camera
        if cam.robot_frames:
            return robot_camera_image(physics.render_camera, (cam.height, cam.width))
        return physics.render_camera(cam.height, cam.width, cam.supersample)

    def _camera_effects(self, image: np.ndarray) -> np.ndarray:
        """The episode's JPEG compression and sensor noise (this step's frame) on ``image``
        (one frame: the batched env applies :meth:`frame_effects` to all its frames at once)."""
        variation = self.variation
        if variation.jpeg_quality:
            image = compress(image, variation.jpeg_quality)
        if variation.noise_std > 0:
            image = add_noise(image, variation.noise_std, variation.noise_seed,
                              self.episode.steps)
        return image

    def frame_effects(self) -> FrameEffects | None:
        """The episode's JPEG compression and sensor noise on this step's frame (None:
        without randomisation)."""
        variation = self.variation
        if variation is None:
            return None
        return FrameEffects(variation.jpeg_quality, variation.noise_std, variation.noise_seed,
                            self.episode.steps)

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

    def mover_features(self, pose: LanePose) -> list[float]:
        """For each of the :data:`MOVERS_REPORTED` nearest movers reaching into the lane ahead
        (:meth:`crllk.tasks.traffic.Traffic.ahead`): distance (m) to its footprint, the lateral
        offsets of its left and right edges from the lane centre (m, positive right) and its
        speed along the lane over the last step (m/s); (MOVER_RANGE, 0, 0, 0) when there is
        none."""
        found = self.traffic.ahead(self.episode.traffic, pose.lane, pose.along, MOVERS_REPORTED,
                                   MOVER_RANGE)
        out: list[float] = []
        for k in range(MOVERS_REPORTED):
            if k < len(found):
                mover = found[k]
                out += [mover.distance, mover.lateral_left, mover.lateral_right, mover.speed]
            else:
                out += [MOVER_RANGE, 0.0, 0.0, 0.0]
        return out

    def state_features(self, physics: Physics) -> np.ndarray:
        """The ``state`` observation; see :func:`state_feature_names`."""
        return np.array(self.state_feature_list(physics))

    def state_feature_list(self, physics: Physics) -> list[float]:
        """:meth:`state_features` as a list of floats."""
        pose = self.lane_pose
        _x, _y, yaw = physics.pose()
        features = [pose.lateral, math.sin(pose.heading_error), math.cos(pose.heading_error),
                    physics.forward_speed(yaw), physics.yaw_rate(),
                    *self.map.curvature_ahead(pose, _CURVATURE_LOOKAHEAD),
                    *self.obstacle_features(pose),
                    *(value for duty in self.episode.history for value in duty)]
        if self.traffic is not None:
            features += self.mover_features(pose)
        return features


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


def physics_of(config: TaskConfig) -> Physics:
    """The compiled scene of a task: its map, motors, randomisation's patches and movers."""
    traffic = config.traffic
    return Physics.from_map(config.map, config.motor, max_delay(config.randomize, config.motor),
                            distractor_count(config.randomize),
                            vehicles=0 if traffic is None else traffic.vehicles.count,
                            pedestrians=0 if traffic is None else traffic.pedestrians.count)


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
    physics = physics_of(config)
    lane_task = LaneKeeping(config, observation=observation, action=action, random=seed)
    steps = config.step_limit()  # a time in seconds for dm-control, a hair under the limit
    return control.Environment(
        physics, lane_task, time_limit=steps * config.control_timestep * (1 - 1e-9),
        control_timestep=config.control_timestep)
