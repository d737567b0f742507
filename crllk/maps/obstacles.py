"""Obstacles in the lane frame: which objects stand on the road ahead, where along the lane and
how far across it.

Every road tile's lanes get the objects whose footprint lies on that tile and across the road
(objects beside the road are left out), each as an interval along the lane and an interval of
lateral offset from the lane centre (positive right, as :class:`~crllk.maps.road.LanePose`).
Following the lanes from a pose gives the obstacles ahead in the robot's travel direction,
nearest first, whichever lane of the road they block.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from crllk.maps.lanes import LANE_OFFSET, Lane
from crllk.maps.objects import MapObject
from crllk.maps.road import DuckietownMap, LanePose

_FOOTPRINT_SAMPLES = 5
"""Points per footprint side sampled to project an object onto a lane."""


@dataclass(frozen=True)
class LaneObstacle:
    """One object as seen from one lane (m): ``along_*`` from the lane's entry edge,
    ``lateral_*`` from its centre line, positive to the right."""

    index: int
    """Position of the object in the map's ``objects``."""
    along_start: float
    along_end: float
    lateral_left: float
    lateral_right: float


@dataclass(frozen=True)
class ObstacleAhead:
    """An obstacle ahead of a pose: ``distance`` (m) along the lanes from the pose to the
    nearest part of its footprint (negative while the robot passes it), ``lateral_left`` and
    ``lateral_right`` (m) the extent of its footprint across the robot's lane, positive right."""

    index: int
    distance: float
    lateral_left: float
    lateral_right: float


def footprint_points(obj: MapObject, samples: int = _FOOTPRINT_SAMPLES) -> list[tuple[float,
                                                                                        float]]:
    """Points (x, y) on the outline of an object's footprint rectangle, and its centre."""
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    points = [(obj.x, obj.y)]
    for k in range(samples):
        t = -0.5 + k / (samples - 1)
        for u, v in ((t * obj.length, -obj.width / 2), (t * obj.length, obj.width / 2),
                     (-obj.length / 2, t * obj.width), (obj.length / 2, t * obj.width)):
            points.append((obj.x + c * u - s * v, obj.y + s * u + c * v))
    return points


def footprint_gap(a: MapObject, b: MapObject) -> float:
    """Distance (m) between the footprints of ``a`` and ``b``, from points on each outline
    (0 when they overlap)."""
    return min(min(_to_rectangle(x, y, b) for x, y in footprint_points(a, 3)),
               min(_to_rectangle(x, y, a) for x, y in footprint_points(b, 3)))


def _to_rectangle(x: float, y: float, obj: MapObject) -> float:
    """Distance (m) from a point to an object's footprint rectangle (0 inside)."""
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    dx, dy = x - obj.x, y - obj.y
    u, v = c * dx + s * dy, -s * dx + c * dy
    return math.hypot(max(abs(u) - obj.length / 2, 0.0), max(abs(v) - obj.width / 2, 0.0))


def road_band(dmap: DuckietownMap) -> tuple[float, float]:
    """Lateral offsets (m, positive right) of the road's left and right edges from a lane."""
    half = dmap.tile_size / 2
    return -(half + LANE_OFFSET), half - LANE_OFFSET


class ObstacleIndex:
    """The map's objects that stand on the road, per lane; see the module docstring. Objects the
    robot does not collide with (:attr:`~crllk.maps.objects.MapObject.collidable`) are left
    out."""

    def __init__(self, dmap: DuckietownMap) -> None:
        self.map = dmap
        left_edge, right_edge = road_band(dmap)
        # Footprint points of each object the robot collides with, by the tile they lie on.
        by_tile: dict[tuple[int, int], list[tuple[int, list[tuple[float, float]]]]] = {}
        for index, obj in enumerate(dmap.objects):
            if not obj.collidable:
                continue
            points: dict[tuple[int, int] | None, list[tuple[float, float]]] = {}
            for p in footprint_points(obj):
                points.setdefault(dmap.tile_index(*p), []).append(p)
            for tile, on_tile in points.items():
                if tile is not None:
                    by_tile.setdefault(tile, []).append((index, on_tile))
        self._by_lane: dict[Lane, tuple[LaneObstacle, ...]] = {}
        for lane in dmap.lanes:
            found = []
            for index, on_tile in by_tile.get((lane.column, lane.row), ()):
                projections = [lane.project(x, y) for x, y in on_tile]
                lateral = [p.lateral for p in projections]
                if max(lateral) < left_edge or min(lateral) > right_edge:
                    continue
                along = [min(max(p.along, 0.0), lane.length) for p in projections]
                found.append(LaneObstacle(index, min(along), max(along), min(lateral),
                                          max(lateral)))
            self._by_lane[lane] = tuple(sorted(found, key=lambda o: o.along_start))
        self._previous = {}
        for lane in dmap.lanes:
            following = dmap.next_lane(lane)
            if following is not None:
                self._previous.setdefault(following, lane)

    def on_lane(self, lane: Lane) -> tuple[LaneObstacle, ...]:
        """The obstacles of one lane, by their start along it."""
        return self._by_lane[lane]

    def previous_lane(self, lane: Lane) -> Lane | None:
        """A lane that continues into ``lane``, or None."""
        return self._previous.get(lane)

    @property
    def on_road(self) -> tuple[int, ...]:
        """Indices of the map objects that stand on the road somewhere."""
        return tuple(sorted({o.index for lane in self._by_lane.values() for o in lane}))

    def ahead(self, pose: LanePose, count: int, max_distance: float,
              behind: float = 0.12) -> list[ObstacleAhead]:
        """Up to ``count`` obstacles ahead of ``pose`` along its lane and the lanes that
        follow, nearest first: those starting within ``max_distance`` (m) and not ending more
        than ``behind`` (m) behind the pose (the robot's body reaches 0.114 m behind its axle).
        """
        seen: set[int] = set()
        out: list[ObstacleAhead] = []
        lane: Lane | None = pose.lane
        offset = -pose.along  # distance from the pose to the current lane's entry edge
        while lane is not None and offset <= max_distance:
            for obstacle in self._by_lane[lane]:
                start, end = offset + obstacle.along_start, offset + obstacle.along_end
                if start > max_distance or end < -behind or obstacle.index in seen:
                    continue
                seen.add(obstacle.index)
                out.append(ObstacleAhead(obstacle.index, start, obstacle.lateral_left,
                                         obstacle.lateral_right))
            offset += lane.length
            lane = self.map.next_lane(lane)
            if lane is pose.lane:
                break
        out.sort(key=lambda o: o.distance)
        return out[:count]


__all__ = ["LaneObstacle", "ObstacleAhead", "ObstacleIndex", "footprint_gap", "footprint_points",
           "road_band"]
