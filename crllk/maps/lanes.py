"""Exact lane geometry of one road tile: straight lanes and quarter-circle arcs.

Right-hand traffic. A lane is named by the tile edge it enters through and the edge it leaves
through. Straight lanes run 0.117 m right of the road centre line; a turn is a quarter circle
about the tile corner shared by its entry and exit edges, of radius s/2 + 0.117 m (left turn)
or s/2 - 0.117 m (right turn). Projection onto a lane is closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

LANE_OFFSET = 0.117
"""Distance of a lane centre from the road centre line (m)."""

UNIT = {"N": (0.0, 1.0), "E": (1.0, 0.0), "S": (0.0, -1.0), "W": (-1.0, 0.0)}
"""Unit vector of each compass heading in the world frame (x east, y north)."""

OPPOSITE = {"N": "S", "S": "N", "E": "W", "W": "E"}
LEFT_OF = {"N": "W", "W": "S", "S": "E", "E": "N"}
RIGHT_OF = {v: k for k, v in LEFT_OF.items()}


def wrap_angle(angle: float) -> float:
    """Wrap an angle to [-pi, pi) (rad)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class Projection(NamedTuple):
    """A point relative to one lane: offsets in m, ``heading`` of the lane there in rad."""

    lateral: float
    along: float
    heading: float


@dataclass(frozen=True)
class Lane:
    """A lane through one tile, entering through edge ``entry`` and leaving through ``exit``.

    ``turn`` is +1 for a left (counter-clockwise) arc, -1 for a right arc and 0 for a straight.
    For arcs, ``centre`` is the tile corner; for straights, the lane centre point at the entry
    edge. ``start_angle`` is the polar angle of the entry point about ``centre`` (arcs only).
    """

    column: int
    row: int
    entry: str
    exit: str
    turn: int
    centre: tuple[float, float]
    radius: float
    start_heading: float
    start_angle: float
    length: float

    @property
    def curvature(self) -> float:
        """Signed curvature (1/m), positive for left turns."""
        return 0.0 if self.turn == 0 else self.turn / self.radius

    def project(self, x: float, y: float) -> Projection:
        """Signed lateral offset (positive right), distance along the lane, lane heading."""
        lateral, along = self.offsets(x, y)
        return Projection(lateral=lateral, along=along, heading=self.heading_at(x, y))

    def offsets(self, x: float, y: float) -> tuple[float, float]:
        """(lateral, along) of ``project(x, y)``: the same numbers, without the heading."""
        cx, cy = self.centre
        dx, dy = x - cx, y - cy
        if self.turn == 0:
            tx, ty = math.cos(self.start_heading), math.sin(self.start_heading)
            return dx * ty - dy * tx, dx * tx + dy * ty
        return (self.turn * (math.hypot(dx, dy) - self.radius),
                self.turn * wrap_angle(math.atan2(dy, dx) - self.start_angle) * self.radius)

    def along_within(self, x: float, y: float, half_width: float) -> float | None:
        """``project(x, y).along`` where the point lies within ``half_width`` (m) of the lane
        centre, else None: the same numbers, without the heading, and without the angle for
        points outside the band."""
        cx, cy = self.centre
        dx, dy = x - cx, y - cy
        if self.turn == 0:
            tx, ty = math.cos(self.start_heading), math.sin(self.start_heading)
            if abs(dx * ty - dy * tx) > half_width:
                return None
            return dx * tx + dy * ty
        if abs(self.turn * (math.hypot(dx, dy) - self.radius)) > half_width:
            return None
        return self.turn * wrap_angle(math.atan2(dy, dx) - self.start_angle) * self.radius

    def heading_at(self, x: float, y: float) -> float:
        """The lane's heading (rad) at the projection of (x, y): ``project(x, y).heading``."""
        if self.turn == 0:
            return self.start_heading
        cx, cy = self.centre
        return wrap_angle(math.atan2(y - cy, x - cx) + self.turn * math.pi / 2.0)

    def point_at(self, along: float, lateral: float = 0.0) -> tuple[float, float, float]:
        """World pose (x, y, heading) at ``along`` metres from the entry, ``lateral`` right."""
        cx, cy = self.centre
        if self.turn == 0:
            h = self.start_heading
            return (cx + along * math.cos(h) + lateral * math.sin(h),
                    cy + along * math.sin(h) - lateral * math.cos(h), h)
        angle = self.start_angle + self.turn * along / self.radius
        r = self.radius + self.turn * lateral
        return (cx + r * math.cos(angle), cy + r * math.sin(angle),
                wrap_angle(angle + self.turn * math.pi / 2.0))


def build_lane(column: int, row: int, rows: int, tile_size: float, entry: str, exit_: str) -> Lane:
    """The lane of tile (column, row) entering through edge ``entry``, leaving via ``exit_``."""
    s = tile_size
    tile_cx, tile_cy = (column + 0.5) * s, (rows - 1 - row + 0.5) * s
    heading_in = OPPOSITE[entry]
    hx, hy = UNIT[heading_in]
    ex, ey = UNIT[entry]
    # Lane centre where it crosses the entry edge: edge midpoint, shifted right of travel.
    start_x = tile_cx + ex * s / 2 + hy * LANE_OFFSET
    start_y = tile_cy + ey * s / 2 - hx * LANE_OFFSET
    start_heading = math.atan2(hy, hx)
    if exit_ == heading_in:
        return Lane(column, row, entry, exit_, 0, (start_x, start_y), math.inf, start_heading,
                    0.0, s)
    turn = 1 if exit_ == LEFT_OF[heading_in] else -1
    if exit_ != (LEFT_OF if turn == 1 else RIGHT_OF)[heading_in]:
        raise ValueError(f"no lane from edge {entry} to edge {exit_}")
    ox, oy = UNIT[exit_]
    corner = (tile_cx + (ex + ox) * s / 2, tile_cy + (ey + oy) * s / 2)
    radius = s / 2 + turn * LANE_OFFSET
    start_angle = math.atan2(start_y - corner[1], start_x - corner[0])
    return Lane(column, row, entry, exit_, turn, corner, radius, start_heading, start_angle,
                radius * math.pi / 2)
