"""A task's traffic: where its movers start, how they move each control step, and the robot's
headway to the vehicle ahead.

Movers are kinematic (:mod:`crllk.sim.movers`). A vehicle rides the lane centre as the scripted
lane follower aims to (:mod:`crllk.tasks.follower`): at its cruising speed, slower in curves
(the follower's lateral acceleration limit) and slower still behind whatever is ahead in its
lane, the robot included, stopping :data:`~crllk.tasks.following.FOLLOW_GAP` short of it (the
car following of :mod:`crllk.tasks.following`). A pedestrian stands at the roadside of its
crossing, then walks across, waits and walks back. Movers yield: neither moves into the robot,
so every collision is the robot's own doing.

The traffic's state is plain values (:meth:`Traffic.reset` returns it, :meth:`Traffic.step`
updates it in place, the movers' velocities over the step included) kept in the task's episode
state, so snapshots hold it. Each episode takes one number from the task's generator, the
episode's traffic seed; every draw of the episode (start distances, speeds, waits) comes from
generators keyed by it, so a policy's behaviour never shifts the spawns of later episodes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from crllk.maps import DuckietownMap, Lane, MapObject
from crllk.maps.objects import OBJECT_SIZES
from crllk.maps.obstacles import footprint_gap, footprint_points
from crllk.maps.routes import (
    LANE_HALF_WIDTH,
    Route,
    advance,
    crossing,
    distance_ahead,
    opposite_position,
)
from crllk.sim import constants as C
from crllk.sim.movers import PEDESTRIAN_SIZE
from crllk.tasks.follower import FollowerGains
from crllk.tasks.following import (
    CORRIDOR_MARGIN,
    FOLLOW_GAP,
    FOLLOW_TIME,
    FRONT,
    LOOKAHEAD,
    Mover,
    following_speed,
)
from crllk.tasks.traffic_config import START_SPACING, TrafficConfig

Pose = tuple[float, float, float]

YIELD_GAP = 0.02
"""A pedestrian holds while its next step would bring it this close (m) to a Duckiebot."""
ROADSIDE = 0.36
"""Distance (m) from the road centre line at which pedestrians wait: beyond the road tile."""
VEHICLE_HEIGHT = OBJECT_SIZES["duckiebot"][2]
"""Height (m) of a Duckiebot's box in recordings."""
_MAX_LATERAL_ACCELERATION = FollowerGains.max_lateral_acceleration
_REACH_SLACK = 1e-9
"""Added (m) to a reach shortened to where a farther point could no longer change the answer,
so that rounding never leaves out a point that could."""


@dataclass(frozen=True)
class MoverAhead:
    """A mover whose footprint reaches into a lane ahead of a position: ``distance`` (m) along
    the lanes to the nearest part of it in the lane, ``lateral_left`` and ``lateral_right`` (m)
    the extent of its footprint across the lane, positive right, and ``speed`` (m/s) its
    velocity over the last control step along the lane."""

    distance: float
    lateral_left: float
    lateral_right: float
    speed: float


class Traffic:
    """The movers of a task on its map, stepped every ``control_timestep`` (s)."""

    def __init__(self, config: TrafficConfig, dmap: DuckietownMap, control_timestep: float):
        self.config = config
        self.map = dmap
        self.dt = control_timestep
        self.crossings = [crossing(dmap, column, row, ROADSIDE)
                          for column, row in config.pedestrians.crossings]
        self._lane_index = {lane: k for k, lane in enumerate(dmap.lanes)}
        self._measured: tuple[tuple, list[Pose], list[list[tuple[float, float]]]] = ((), [], [])
        """The vehicles' positions (lane index, along), axle poses and outlines last
        measured."""

    @property
    def vehicles(self) -> int:
        return self.config.vehicles.count

    @property
    def pedestrians(self) -> int:
        return self.config.pedestrians.count

    # ----- episode start ----------------------------------------------------------------
    def reset(self, random: np.random.RandomState, lane: Lane, along: float) -> dict[str, Any]:
        """The starting traffic around a robot at ``along`` on ``lane``: one draw from the
        task's generator ``random``, the rest from the episode's traffic seed."""
        seed = int(random.randint(2**31 - 1))
        rng = np.random.default_rng(seed)
        vehicles = self.config.vehicles
        ahead = [advance(self.map, lane, along, d) for d in self._distances(rng, vehicles.ahead)]
        opposite = [opposite_position(self.map, *advance(self.map, lane, along, d))
                    for d in self._distances(rng, vehicles.opposite)]
        speeds = rng.uniform(*vehicles.speed, size=vehicles.count)
        pedestrians = [[int(rng.integers(2)), 0.0, *self._crossing_draws(rng)]
                       for _ in range(self.pedestrians)]
        return {"seed": seed,
                "vehicles": [[self._lane_index[v_lane], v_along, float(speed)]
                             for (v_lane, v_along), speed in zip(ahead + opposite, speeds,
                                                                 strict=True)],
                "pedestrians": pedestrians,
                "velocities": [[0.0, 0.0] for _ in range(self.vehicles + self.pedestrians)]}

    def _distances(self, rng: np.random.Generator, count: int) -> list[float]:
        """``count`` start distances (m) in ``vehicles.distance``, at least
        :data:`START_SPACING` apart: sorted draws from the range shortened by the spacings,
        the k-th pushed k spacings on (uniform over the allowed placements)."""
        low, high = self.config.vehicles.distance
        slack = high - (count - 1) * START_SPACING  # >= low: checked with the task file
        draws = sorted(rng.uniform(low, max(slack, low), size=count).tolist())
        return [d + k * START_SPACING for k, d in enumerate(draws)]

    def _crossing_draws(self, rng: np.random.Generator) -> list[float | int]:
        """[speed (m/s), wait (control steps), crossings done (0)] of a pedestrian's next
        crossing."""
        p = self.config.pedestrians
        speed = float(rng.uniform(*p.speed))
        wait = round(float(rng.uniform(*p.wait)) / self.dt)
        return [speed, wait, 0]

    # ----- stepping ---------------------------------------------------------------------
    def step(self, state: dict[str, Any], robot: Pose) -> list[Pose]:
        """Move every mover one control step, with the robot at ``robot`` (axle pose), and
        keep their velocities (m/s, world frame) over the step in ``state["velocities"]``;
        returns their :meth:`poses` after the step (the vehicles' as :meth:`_measure` has
        them: a subclass that overrides :meth:`poses` overrides this too)."""
        robot_box = duckiebot_box(*robot)
        robot_points = outline(robot_box)
        vehicle_poses, vehicle_points = map(list, self._measure(state))  # copies, changed below
        before = vehicle_poses + self._pedestrian_poses(state)
        pedestrian_points = [p for pose in before[self.vehicles:]
                             for p in outline(pedestrian_box(*pose))]
        vehicle_boxes = []
        for k, vehicle in enumerate(state["vehicles"]):
            others = [p for j, points in enumerate(vehicle_points) if j != k for p in points]
            lane = self.map.lanes[vehicle[0]]
            speed = self._vehicle_speed(lane, vehicle[1], vehicle[2],
                                        robot_points + others + pedestrian_points)
            lane, vehicle[1] = advance(self.map, lane, vehicle[1], speed * self.dt)
            vehicle[0] = self._lane_index[lane]
            vehicle_poses[k] = lane.point_at(vehicle[1])
            vehicle_boxes.append(duckiebot_box(*vehicle_poses[k]))
            vehicle_points[k] = outline(vehicle_boxes[k])
        self._measured = (_positions(state), vehicle_poses, vehicle_points)
        for k, pedestrian in enumerate(state["pedestrians"]):
            self._walk(state["seed"], k, pedestrian, [robot_box, *vehicle_boxes])
        after = vehicle_poses + self._pedestrian_poses(state)
        state["velocities"] = [[(x1 - x0) / self.dt, (y1 - y0) / self.dt]
                               for (x0, y0, _), (x1, y1, _) in zip(before, after, strict=True)]
        return after

    def _vehicle_speed(self, lane: Lane, along: float, cruise: float,
                       points: list[tuple[float, float]]) -> float:
        """Speed (m/s) of a vehicle at ``along`` on ``lane`` for this step."""
        speed = cruise
        if lane.curvature:
            speed = min(speed, math.sqrt(_MAX_LATERAL_ACCELERATION / abs(lane.curvature)))
        # Beyond where following_speed reaches ``speed``, nothing ahead slows the vehicle.
        slowing_reach = FRONT + FOLLOW_GAP + FOLLOW_TIME * speed + _REACH_SLACK
        ahead = distance_ahead(self.map, lane, along, points,
                               C.FOOTPRINT_WIDTH / 2 + CORRIDOR_MARGIN,
                               min(LOOKAHEAD, slowing_reach))
        if ahead is not None:
            speed = min(speed, following_speed(ahead - FRONT, FOLLOW_GAP))
        return speed

    def _walk(self, seed: int, k: int, pedestrian: list, duckiebots: list[MapObject]) -> None:
        """One step of pedestrian ``k``: wait, or walk on unless that would bring it within
        :data:`YIELD_GAP` of a Duckiebot; at the far side, draw the next crossing."""
        side, walked, speed, wait, done = pedestrian
        if wait > 0:
            pedestrian[3] = wait - 1
            return
        crossing_k = self.crossings[k]
        walked = min(walked + speed * self.dt, crossing_k.length)
        box = pedestrian_box(*crossing_k.point_at(walked, side))
        if any(footprint_gap(box, other) < YIELD_GAP for other in duckiebots):
            return
        if walked < crossing_k.length:
            pedestrian[1] = walked
            return
        rng = np.random.default_rng([seed, k, done + 1])
        pedestrian[:] = [1 - side, 0.0, *self._crossing_draws(rng)[:2], done + 1]

    # ----- poses and measures -----------------------------------------------------------
    def poses(self, state: dict[str, Any]) -> list[Pose]:
        """(x, y, yaw) of every mover: the vehicles' axles, then the pedestrians."""
        return self._measure(state)[0] + self._pedestrian_poses(state)

    def _pedestrian_poses(self, state: dict[str, Any]) -> list[Pose]:
        """(x, y, yaw) of every pedestrian."""
        return [self.crossings[k].point_at(walked, side)
                for k, (side, walked, *_rest) in enumerate(state["pedestrians"])]

    def boxes(self, state: dict[str, Any]) -> list[MapObject]:
        """Every mover's footprint box (with its height), in :meth:`poses`' order."""
        return _boxes(self.poses(state), self.vehicles)

    def movers(self, state: dict[str, Any]) -> list[Mover]:
        """Every mover's footprint box and velocity over the last step, in :meth:`poses`'
        order (at rest on an episode's first step, and in a state kept without velocities)."""
        boxes = self.boxes(state)
        velocities = state.get("velocities") or [[0.0, 0.0]] * len(boxes)
        return [Mover(box, (vx, vy)) for box, (vx, vy) in zip(boxes, velocities, strict=True)]

    def headway(self, state: dict[str, Any], lane: Lane, along: float) -> float | None:
        """Gap (m) from the front of a robot at ``along`` on ``lane`` to the nearest vehicle
        whose footprint reaches into that lane ahead (within :data:`LOOKAHEAD` or the headway
        bound, whichever is longer), or None: the measure itself (the headway signal needs
        only :meth:`within_headway`)."""
        return self._gap_ahead(state, lane, along, max(LOOKAHEAD, self.config.headway))

    def within_headway(self, state: dict[str, Any], lane: Lane, along: float) -> bool:
        """Whether :meth:`headway` is below the headway bound, measured no farther than the
        bound reaches."""
        bound = self.config.headway
        gap = self._gap_ahead(state, lane, along, bound + _REACH_SLACK)
        return gap is not None and gap < bound

    def _gap_ahead(self, state: dict[str, Any], lane: Lane, along: float,
                   reach: float) -> float | None:
        """Gap (m) from the front of a robot at ``along`` on ``lane`` to the nearest vehicle
        whose footprint reaches into that lane within ``reach`` (m) of the front, or None."""
        points = [p for vehicle in self._vehicle_outlines(state) for p in vehicle]
        ahead = distance_ahead(self.map, lane, along, points, LANE_HALF_WIDTH, reach + FRONT)
        return None if ahead is None else ahead - FRONT

    def _measure(self, state: dict[str, Any]) -> tuple[list[Pose], list[list[tuple[float, float]]]]:
        """Each vehicle's axle pose and :func:`outline` where ``state`` has it (the last
        :meth:`step`'s, unless the vehicles stand elsewhere)."""
        positions, poses, outlines = self._measured
        if positions != _positions(state):
            poses = [self.map.lanes[lane].point_at(along) for lane, along, _ in state["vehicles"]]
            outlines = [outline(duckiebot_box(*pose)) for pose in poses]
            self._measured = (_positions(state), poses, outlines)
        return poses, outlines

    def _vehicle_outlines(self, state: dict[str, Any]) -> list[list[tuple[float, float]]]:
        """Each vehicle's :func:`outline` where ``state`` has it."""
        return self._measure(state)[1]

    def ahead(self, state: dict[str, Any], lane: Lane, along: float, count: int,
              reach: float) -> list[MoverAhead]:
        """Up to ``count`` movers whose footprint reaches into the lane (within
        ``LANE_HALF_WIDTH`` of its centre) ahead of ``along`` on ``lane``, within ``reach`` (m)
        along the lanes, nearest first. The extent across the lane is that of the footprint's
        points on the route; the speed is along the lane where the mover is nearest."""
        route = Route(self.map, lane, along, reach)
        found = []
        for box, (vx, vy) in self.movers(state):
            points = [(located, x, y) for x, y in dict.fromkeys(footprint_points(box))
                      if (located := route.locate(x, y)) is not None]
            inside = [p for p in points if abs(p[0][1]) <= LANE_HALF_WIDTH]
            if not inside:
                continue
            (distance, _, nearest_lane), x, y = min(inside, key=lambda p: p[0][0])
            heading = nearest_lane.heading_at(x, y)
            speed = vx * math.cos(heading) + vy * math.sin(heading)
            laterals = [p[0][1] for p in points]
            found.append(MoverAhead(distance, min(laterals), max(laterals), speed))
        found.sort(key=lambda m: m.distance)
        return found[:count]


def outline(box: MapObject) -> list[tuple[float, float]]:
    """The points (x, y) the traffic measures a footprint by: its centre, corners and edge
    midpoints, the distinct points of ``footprint_points(box, 3)`` in its order and computed as
    it computes them."""
    x, y, c, s = box.x, box.y, math.cos(box.yaw), math.sin(box.yaw)
    half_length, half_width = box.length / 2, box.width / 2
    return [(x, y)] + [(x + c * u - s * v, y + s * u + c * v)
                       for u, v in ((-half_length, -half_width), (-half_length, half_width),
                                    (half_length, -half_width), (0.0, -half_width),
                                    (0.0, half_width), (-half_length, 0.0),
                                    (half_length, 0.0), (half_length, half_width))]


def _positions(state: dict[str, Any]) -> tuple[tuple[int, float], ...]:
    """Where the vehicles of a traffic state are: (lane index, along) each."""
    return tuple((lane, along) for lane, along, _ in state["vehicles"])


def _boxes(poses: list[Pose], vehicles: int) -> list[MapObject]:
    """The footprint boxes of movers at ``poses``, the first ``vehicles`` of them vehicles."""
    return ([duckiebot_box(*pose) for pose in poses[:vehicles]]
            + [pedestrian_box(*pose) for pose in poses[vehicles:]])


def duckiebot_box(x: float, y: float, yaw: float) -> MapObject:
    """The collision footprint of a Duckiebot whose axle is at (x, y, yaw)."""
    back = C.FOOTPRINT_CENTRE_BEHIND_AXLE
    return MapObject("duckiebot", x - back * math.cos(yaw), y - back * math.sin(yaw), yaw,
                     C.FOOTPRINT_LENGTH, C.FOOTPRINT_WIDTH, VEHICLE_HEIGHT)


def pedestrian_box(x: float, y: float, yaw: float) -> MapObject:
    """The footprint of a pedestrian at (x, y, yaw)."""
    length, width, height = PEDESTRIAN_SIZE
    return MapObject("duckie", x, y, yaw, length, width, height)


__all__ = ["FOLLOW_GAP", "FRONT", "ROADSIDE", "MoverAhead", "Traffic", "duckiebot_box", "outline",
           "pedestrian_box"]
