"""Where moving agents go: along the lanes (vehicles) and across the road (pedestrians).

A position on the road network is a lane and a distance along it from the lane's entry edge.
Vehicles move by :func:`advance`, which follows :meth:`DuckietownMap.next_lane` (straight on at
intersections) and stops at the end of an open road. :func:`distance_ahead` measures, in the
lane frame, how far ahead along a route the nearest of some points lies within a band about
the lane centre (what a vehicle keeps its distance to, and the robot's headway); a :class:`Route`
measures single points against the lanes ahead.
A :class:`Crossing` is a straight walk across a straight road tile through its centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from crllk.maps.lanes import Lane
from crllk.maps.road import DuckietownMap

LANE_HALF_WIDTH = 0.105
"""Half the lane's width (m): 21 cm from the white line's inner edge to the yellow line."""


def advance(dmap: DuckietownMap, lane: Lane, along: float,
            distance: float) -> tuple[Lane, float]:
    """The position ``distance`` (m, non-negative) further along the lanes from ``along`` on
    ``lane``; at the end of an open road, that end."""
    along += distance
    while along > lane.length:
        following = dmap.next_lane(lane)
        if following is None:
            return lane, lane.length
        along -= lane.length
        lane = following
    return lane, along


def opposite_lane(dmap: DuckietownMap, lane: Lane) -> Lane | None:
    """The lane of the same tile that runs the other way (entering where ``lane`` leaves)."""
    return next((other for other in dmap.tile_lanes(lane.column, lane.row)
                 if other.entry == lane.exit and other.exit == lane.entry), None)


def opposite_position(dmap: DuckietownMap, lane: Lane, along: float) -> tuple[Lane, float]:
    """The position in the opposite lane beside ``along`` on ``lane``.

    Raises:
        ValueError: if no lane of the tile runs the other way.
    """
    other = opposite_lane(dmap, lane)
    if other is None:
        raise ValueError(f"tile {lane.column, lane.row} has no lane from {lane.exit} to "
                         f"{lane.entry}")
    x, y, _ = lane.point_at(along)
    return other, min(max(other.project(x, y).along, 0.0), other.length)


class RoutePoint(NamedTuple):
    """A point measured against a :class:`Route`."""

    distance: float
    """Distance (m) along the lanes from the route's start to the point's projection."""
    lateral: float
    """Offset (m) from the centre of the route's lane on the point's tile, positive right."""
    heading: float
    """Heading (rad) of that lane at the projection."""


class Route:
    """The lanes ahead of ``along`` on ``lane`` (following :meth:`DuckietownMap.next_lane`) up
    to ``reach`` (m), one per tile: the first lane the route takes through each tile."""

    def __init__(self, dmap: DuckietownMap, lane: Lane, along: float, reach: float) -> None:
        self.map = dmap
        self.reach = reach
        self._on_tile: dict[tuple[int, int], tuple[Lane, float]] = {}
        """The route's lane on each tile and the distance (m) from the start to its entry."""
        offset, current = -along, lane
        while current is not None and offset <= reach:
            self._on_tile.setdefault((current.column, current.row), (current, offset))
            offset += current.length
            current = dmap.next_lane(current)
            if current is lane:
                break

    def project(self, x: float, y: float) -> RoutePoint | None:
        """The point (x, y) against the route's lane on its tile; None off the route's tiles
        or outside 0 to ``reach`` (m) along it."""
        found = self._on_tile.get(self.map.tile_index(x, y))
        if found is None:
            return None
        lane, start = found
        projection = lane.project(x, y)
        distance = start + projection.along
        if not 0.0 <= distance <= self.reach:
            return None
        return RoutePoint(distance, projection.lateral, projection.heading)

    def locate(self, x: float, y: float) -> tuple[float, float, Lane] | None:
        """(distance, lateral, lane) of ``project(x, y)`` without the heading (the lane's
        ``heading_at(x, y)`` gives it), or None where ``project`` gives None."""
        found = self._on_tile.get(self.map.tile_index(x, y))
        if found is None:
            return None
        lane, start = found
        lateral, along = lane.offsets(x, y)
        distance = start + along
        if not 0.0 <= distance <= self.reach:
            return None
        return distance, lateral, lane

    def nearest_within(self, points: list[tuple[float, float]],
                       half_width: float) -> float | None:
        """The least ``project(x, y).distance`` of the ``points`` that lie within
        ``half_width`` (m) of their lane's centre (None if none does). The route's tiles are
        looked up by their indices directly: a point off the grid is on none of them."""
        size, top, on_tile, reach = self.map.tile_size, self.map.rows - 1, self._on_tile, self.reach
        floor = math.floor
        nearest = None
        for x, y in points:
            found = on_tile.get((floor(x / size), top - floor(y / size)))
            if found is None:
                continue
            lane, start = found
            along = lane.along_within(x, y, half_width)
            if along is None:
                continue
            distance = start + along
            if 0.0 <= distance <= reach and (nearest is None or distance < nearest):
                nearest = distance
        return nearest


def distance_ahead(dmap: DuckietownMap, lane: Lane, along: float,
                   points: list[tuple[float, float]], half_width: float,
                   reach: float) -> float | None:
    """Distance (m) along the lanes from ``along`` on ``lane`` to the nearest of ``points``
    ahead that lies within ``half_width`` (m) of the lane centre, up to ``reach`` (m); None
    when there is none. Each point is measured against the route's lane on its tile.

    A point farther than ``reach + half_width`` (m) in a straight line from the start cannot
    count (the lanes' length to its projection is at least the straight line there), so it is
    left out before it is projected, and when no point is that near, no route is built: the
    same answer, sooner."""
    start_x, start_y, _ = lane.point_at(along)
    limit = (reach + half_width) ** 2
    near = [(x, y) for x, y in points if (x - start_x) ** 2 + (y - start_y) ** 2 <= limit]
    if not near:
        return None
    return Route(dmap, lane, along, reach).nearest_within(near, half_width)


@dataclass(frozen=True)
class Crossing:
    """A walk across the straight road tile (``column``, ``row``) through its centre,
    perpendicular to the road, from ``reach`` (m) beyond the road centre line on one side to as
    far on the other. ``side`` 0 starts on the right of the tile's lane heading ``heading``
    (rad), side 1 on its left."""

    column: int
    row: int
    centre: tuple[float, float]
    heading: float
    """Heading (rad) of one of the tile's lanes (the other runs the opposite way)."""
    reach: float

    @property
    def length(self) -> float:
        """Length of the walk (m)."""
        return 2.0 * self.reach

    def point_at(self, walked: float, side: int) -> tuple[float, float, float]:
        """World pose (x, y, heading) after walking ``walked`` metres from ``side``."""
        # Side 0 starts right of ``heading`` and walks left: heading + pi/2.
        direction = self.heading + (math.pi / 2 if side == 0 else -math.pi / 2)
        start = self.reach - walked
        cx, cy = self.centre
        return (cx - start * math.cos(direction), cy - start * math.sin(direction),
                math.atan2(math.sin(direction), math.cos(direction)))


def crossing(dmap: DuckietownMap, column: int, row: int, reach: float) -> Crossing:
    """The :class:`Crossing` of straight road tile (``column``, ``row``).

    Raises:
        ValueError: if the tile is off the map or not a straight road.
    """
    if not (0 <= column < dmap.columns and 0 <= row < dmap.rows):
        raise ValueError(f"tile {[column, row]} is off the {dmap.columns}x{dmap.rows} map")
    tile = dmap.tile(column, row)
    if tile.kind != "straight":
        raise ValueError(f"tile {[column, row]} is {tile.label!r}, not a straight road")
    s = dmap.tile_size
    centre = ((column + 0.5) * s, (dmap.rows - 1 - row + 0.5) * s)
    return Crossing(column, row, centre, dmap.tile_lanes(column, row)[0].start_heading, reach)


__all__ = ["LANE_HALF_WIDTH", "Crossing", "Route", "RoutePoint", "advance", "crossing",
           "distance_ahead", "opposite_lane", "opposite_position"]
