"""The road network of a map: tile openings, lanes, lane poses and lane-centre loops."""

from __future__ import annotations

import math
from dataclasses import dataclass

from crllk.errors import MapError
from crllk.maps.format import MapSpec, Tile
from crllk.maps.lanes import LEFT_OF, OPPOSITE, RIGHT_OF, UNIT, Lane, build_lane, wrap_angle
from crllk.maps.objects import MapObject

_ALIGNED_COS = math.cos(math.radians(45.0))
"""Lanes whose heading is within 45 degrees of the robot's count as its travel direction."""
HEADING_WEIGHT = 0.2
"""Where several lanes run the robot's way (intersections), the lane pose is taken against the
one nearest in lateral offset plus this many metres per radian of heading difference (m/rad)."""


def openings(tile: Tile) -> tuple[str, ...]:
    """The edges (N, E, S, W) through which a road tile connects to its neighbours.

    Curves: ``curve_left/D`` is entered heading D and exits heading D turned left, so it
    joins edge opposite(D) with edge left(D). Three-way tiles are a straight road along D
    with a branch to the named side (``3way_left/D`` branches left of D).
    """
    kind, d = tile.kind, tile.orientation
    if kind == "straight":
        return (d, OPPOSITE[d])
    if kind == "curve_left":
        return (OPPOSITE[d], LEFT_OF[d])
    if kind == "curve_right":
        return (OPPOSITE[d], RIGHT_OF[d])
    if kind == "3way_left":
        return (OPPOSITE[d], d, LEFT_OF[d])
    if kind == "3way_right":
        return (OPPOSITE[d], d, RIGHT_OF[d])
    if kind == "4way":
        return ("N", "E", "S", "W")
    return ()


def named_lane(tile: Tile) -> tuple[str, str] | None:
    """(entry, exit) edges of the turn a curve tile's orientation names; None otherwise."""
    if tile.kind == "curve_left":
        return OPPOSITE[tile.orientation], LEFT_OF[tile.orientation]
    if tile.kind == "curve_right":
        return OPPOSITE[tile.orientation], RIGHT_OF[tile.orientation]
    return None


def _lane_key(lane: Lane) -> tuple[int, int, str, str]:
    """(column, row, entry, exit): identifies a lane of a map."""
    return lane.column, lane.row, lane.entry, lane.exit


@dataclass(frozen=True)
class LanePose:
    """A world pose relative to the lane of the travel direction best aligned with its yaw.

    Attributes:
        lateral: signed offset from the lane centre (m), positive to the right.
        heading_error: yaw minus lane heading, wrapped to [-pi, pi) (rad).
        on_road: whether the point lies on a drivable tile.
        along: distance from the lane's entry edge along the lane (m).
        lane: the lane measured against (on the nearest road tile when off the road).
    """

    lateral: float
    heading_error: float
    on_road: bool
    along: float
    lane: Lane

    @property
    def tile(self) -> tuple[int, int]:
        """(column, row) of the lane's tile."""
        return self.lane.column, self.lane.row

    @property
    def curvature(self) -> float:
        """Signed curvature of the lane here (1/m), positive for left turns."""
        return self.lane.curvature


class DuckietownMap:
    """A validated map with its exact lane geometry."""

    def __init__(self, spec: MapSpec) -> None:
        self.spec = spec
        self.name = spec.name
        self.tile_size = spec.tile_size
        self.rows, self.columns = spec.rows, spec.columns
        self.objects: tuple[MapObject, ...] = spec.objects
        self.road_tiles: tuple[Tile, ...] = tuple(
            t for row in spec.tiles for t in row if t.drivable)
        if not self.road_tiles:
            raise MapError(spec.source, "tiles", "the map has no drivable tile")
        self.dead_ends: tuple[tuple[int, int, str], ...] = tuple(self._check_connections())
        """Road openings (column, row, edge) off the map or onto a tile that is not road."""
        self._lanes: dict[tuple[int, int, str], list[Lane]] = {}
        for t in self.road_tiles:
            edges = openings(t)
            for entry in edges:
                self._lanes[(t.column, t.row, entry)] = [
                    build_lane(t.column, t.row, self.rows, self.tile_size, entry, exit_)
                    for exit_ in edges if exit_ != entry]
        self.lanes: tuple[Lane, ...] = tuple(ln for v in self._lanes.values() for ln in v)
        # Lookup tables for the per-step queries.
        self._drivable = [[t.drivable for t in row] for row in spec.tiles]
        self._tile_lanes = {(t.column, t.row): tuple(ln for e in openings(t)
                                                     for ln in self._lanes[(t.column, t.row, e)])
                            for t in self.road_tiles}
        self._next_lanes = {_lane_key(ln): self._find_next_lane(ln) for ln in self.lanes}
        self._directions: dict[Lane, str] | None = None  # built by direction_of

    # ----- grid -------------------------------------------------------------------------
    @property
    def width(self) -> float:
        """Extent of the map along x (m)."""
        return self.columns * self.tile_size

    @property
    def height(self) -> float:
        """Extent of the map along y (m)."""
        return self.rows * self.tile_size

    def tile(self, column: int, row: int) -> Tile:
        return self.spec.tiles[row][column]

    def tile_index(self, x: float, y: float) -> tuple[int, int] | None:
        """(column, row) of the tile under a world point, or None off the grid."""
        column = math.floor(x / self.tile_size)
        row = self.rows - 1 - math.floor(y / self.tile_size)
        if 0 <= column < self.columns and 0 <= row < self.rows:
            return column, row
        return None

    def offroad_cells(self, border: int = 1) -> list[tuple[float, float]]:
        """South-west corners (x, y) (m) of the tile-sized cells off the road: the map's tiles
        that are not drivable and a ring ``border`` cells wide around the map."""
        s = self.tile_size
        return [(column * s, (self.rows - 1 - row) * s)
                for row in range(-border, self.rows + border)
                for column in range(-border, self.columns + border)
                if not (0 <= row < self.rows and 0 <= column < self.columns
                        and self._drivable[row][column])]

    def is_road(self, x: float, y: float) -> bool:
        """Whether a world point lies on a drivable tile."""
        column = math.floor(x / self.tile_size)
        row = self.rows - 1 - math.floor(y / self.tile_size)
        return 0 <= column < self.columns and 0 <= row < self.rows and self._drivable[row][column]

    def all_road(self, points: list[tuple[float, float]]) -> bool:
        """Whether every world point (x, y) lies on a drivable tile."""
        return all(self.is_road(x, y) for x, y in points)

    def tile_lanes(self, column: int, row: int) -> list[Lane]:
        """All lanes of a road tile."""
        return list(self._tile_lanes.get((column, row), ()))

    # ----- lane pose --------------------------------------------------------------------
    def lane_pose(self, x: float, y: float, yaw: float) -> LanePose:
        """Lane-relative pose of (x, y, yaw) on the tile under it (the nearest road tile off
        the road), against the lane best aligned with ``yaw``."""
        index = self.tile_index(x, y)
        on_road = index is not None and self._drivable[index[1]][index[0]]
        if not on_road:
            index = self._nearest_road_tile(x, y)
        lane, proj = self._best_lane(self._tile_lanes[index], x, y, yaw)
        return LanePose(proj.lateral, wrap_angle(yaw - proj.heading), on_road, proj.along, lane)

    def _best_lane(self, lanes: tuple[Lane, ...], x: float, y: float, yaw: float):
        best = None
        for lane in lanes:
            proj = lane.project(x, y)
            alignment = math.cos(yaw - proj.heading)
            # Aligned lanes first, then the closest of them in offset and heading (several
            # only on intersections), else the best aligned.
            if alignment >= _ALIGNED_COS:
                key = (False, abs(proj.lateral)
                       + HEADING_WEIGHT * abs(wrap_angle(yaw - proj.heading)))
            else:
                key = (True, -alignment)
            if best is None or key < best[0]:
                best = (key, lane, proj)
        return best[1], best[2]

    def _nearest_road_tile(self, x: float, y: float) -> tuple[int, int]:
        s = self.tile_size

        def distance(t: Tile) -> float:
            x0, y0 = t.column * s, (self.rows - 1 - t.row) * s
            return math.hypot(max(x0 - x, 0.0, x - x0 - s), max(y0 - y, 0.0, y - y0 - s))

        t = min(self.road_tiles, key=distance)
        return t.column, t.row

    # ----- following lanes --------------------------------------------------------------
    def next_lane(self, lane: Lane) -> Lane | None:
        """The lane that continues ``lane`` on the neighbouring tile (straight through at
        intersections), or None where the road ends."""
        key = _lane_key(lane)
        if key in self._next_lanes:
            return self._next_lanes[key]
        return self._find_next_lane(lane)

    def _find_next_lane(self, lane: Lane) -> Lane | None:
        dx, dy = UNIT[lane.exit]
        column, row = lane.column + int(dx), lane.row - int(dy)
        candidates = self._lanes.get((column, row, OPPOSITE[lane.exit]))
        if not candidates:
            return None
        for c in candidates:
            if c.exit == lane.exit:
                return c
        return candidates[0]

    def curvature_ahead(self, pose: LanePose, distances: tuple[float, ...]) -> list[float]:
        """Lane curvature (1/m) at each distance (m) ahead of ``pose`` along its lane."""
        ahead: list[Lane | None] = [pose.lane]  # the lanes from here on, found as needed
        out = []
        for d in distances:
            k, remaining = 0, pose.along + d
            while ahead[k] is not None and remaining > ahead[k].length:
                remaining -= ahead[k].length
                k += 1
                if k == len(ahead):
                    ahead.append(self.next_lane(ahead[k - 1]))
            out.append(0.0 if ahead[k] is None else ahead[k].curvature)
        return out

    def lap_length(self, direction: str = "intended") -> float:
        """Length (m) of the lane-centre loop in the ``intended`` or ``reverse`` direction.

        The intended direction is the one in which most curve tiles are driven through the
        turn their orientation names.
        """
        if direction not in ("intended", "reverse"):
            raise ValueError(f"direction must be 'intended' or 'reverse', got {direction!r}")
        loops = [self.loop(first) for first in self._loop_starts()]
        loops.sort(key=lambda lanes: -self._named_turns(lanes))
        lanes = loops[0] if direction == "intended" else loops[1]
        return sum(lane.length for lane in lanes)

    def direction_of(self, lane: Lane) -> str | None:
        """``"intended"`` or ``"reverse"``: which loop of the map ``lane`` belongs to (None on
        maps whose road is not a single loop, e.g. with intersections)."""
        if self._directions is None:
            try:
                loops = sorted((self.loop(first) for first in self._loop_starts()),
                               key=lambda lanes: -self._named_turns(lanes))
            except MapError:
                loops = []
            self._directions = {}
            if len(loops) == 2 and len(loops[0]) + len(loops[1]) == len(self.lanes):
                self._directions = {**dict.fromkeys(loops[1], "reverse"),
                                    **dict.fromkeys(loops[0], "intended")}
        return self._directions.get(lane)

    def loop(self, first: Lane) -> list[Lane]:
        """The closed sequence of lanes followed from ``first``.

        Raises:
            MapError: if following the road from ``first`` does not come back to it.
        """
        lanes, lane, seen = [first], self.next_lane(first), {first}
        while lane is not None and lane != first:
            if lane in seen:
                break
            lanes.append(lane)
            seen.add(lane)
            lane = self.next_lane(lane)
        if lane != first:
            raise MapError(self.spec.source, "tiles",
                           f"the road from tile {first.column, first.row} is not a closed loop")
        return lanes

    def _loop_starts(self) -> tuple[Lane, Lane]:
        t = self.road_tiles[0]
        a, b = openings(t)[:2]
        return (self._lane_between(t, a, b), self._lane_between(t, b, a))

    def _lane_between(self, t: Tile, entry: str, exit_: str) -> Lane:
        return next(ln for ln in self._lanes[(t.column, t.row, entry)] if ln.exit == exit_)

    def _named_turns(self, lanes: list[Lane]) -> int:
        return sum(named_lane(self.tile(ln.column, ln.row)) == (ln.entry, ln.exit)
                   for ln in lanes)

    # ----- validation -------------------------------------------------------------------
    def _check_connections(self) -> list[tuple[int, int, str]]:
        """The dead ends (column, row, edge): road openings off the map or onto a tile that is
        not road, where driving on leaves the road.

        Raises:
            MapError: where a road tile opens onto a road tile that does not open back.
        """
        dead_ends = []
        for t in self.road_tiles:
            for edge in openings(t):
                dx, dy = UNIT[edge]
                column, row = t.column + int(dx), t.row - int(dy)
                if not (0 <= column < self.columns and 0 <= row < self.rows):
                    dead_ends.append((t.column, t.row, edge))
                    continue
                other = self.tile(column, row)
                if not other.drivable:
                    dead_ends.append((t.column, t.row, edge))
                elif OPPOSITE[edge] not in openings(other):
                    raise MapError(self.spec.source, f"tiles[{t.row}][{t.column}]",
                                   f"{t.label!r} opens to the {edge} onto {other.label!r} at "
                                   f"tiles[{row}][{column}], which does not open back: "
                                   "the road does not connect")
        return dead_ends
