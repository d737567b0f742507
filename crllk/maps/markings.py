"""The map's lines as 3D polylines: lane centres and the white and yellow tape, in numpy.

Each strip is an array ``[K, 3]`` of points (x east, y north, z up, m) sampled every 2 cm
along a lane. The tape lies where the floor texture (:mod:`crllk.sim.texture`) paints it;
:mod:`crllk.recording.scene` draws these strips over the tiles.
"""

from __future__ import annotations

import math

import numpy as np

from crllk.maps.lanes import LANE_OFFSET, OPPOSITE, RIGHT_OF, Lane
from crllk.maps.road import DuckietownMap, openings

WHITE_INNER = 0.015
"""Distance of the white tape's outer edge from the tile edge (m)."""
WHITE_WIDTH = 0.048
YELLOW_WIDTH = 0.024
"""Widths of the white edge tape and of the yellow centre tape (m)."""
DASH_LENGTH = 0.05
GAP_LENGTH = 0.025
"""Length of the yellow dashes and of the gaps between them (m)."""

_LINE_SPACING = 0.02
"""Sample spacing of lane and marking polylines (m)."""
MARKING_HEIGHT = 0.002
LANE_HEIGHT = 0.004
"""Heights of marking and lane-centre lines above the floor (m), drawn over the tiles."""


def lane_polyline(lane: Lane, lateral: float = 0.0, start: float = 0.0,
                  stop: float | None = None, z: float = 0.0) -> np.ndarray:
    """Points ``[K, 3]`` along ``lane`` from ``start`` to ``stop`` m (default: its end),
    ``lateral`` m right of its centre line, at height ``z`` (m)."""
    stop = lane.length if stop is None else stop
    count = max(2, math.ceil((stop - start) / _LINE_SPACING) + 1)
    points = [lane.point_at(a, lateral)[:2] for a in np.linspace(start, stop, count)]
    return np.column_stack([np.asarray(points), np.full(count, z)])


def lane_centre_strips(dmap: DuckietownMap) -> list[np.ndarray]:
    """The centre line of every lane of the map (both directions, every turn)."""
    return [lane_polyline(lane, z=LANE_HEIGHT) for lane in dmap.lanes]


def white_lateral(tile_size: float) -> float:
    """Offset of the white edge tape's middle right of the lane centre (m), as the floor
    texture (:mod:`crllk.sim.texture`) paints it."""
    return tile_size / 2 - WHITE_INNER - WHITE_WIDTH / 2 - LANE_OFFSET


def lane_edges(tile_size: float) -> tuple[float, float]:
    """Offsets (m, positive right) of the lane's two edges from its centre: the yellow centre
    tape's inner edge on the left, the white edge tape's inner edge on the right."""
    return -(LANE_OFFSET - YELLOW_WIDTH / 2), white_lateral(tile_size) - WHITE_WIDTH / 2


def white_marking_strips(dmap: DuckietownMap) -> list[np.ndarray]:
    """White edge tape: right of every lane on straights and curves; along the closed side of
    intersections (right of the straight lanes whose right side has no opening)."""
    lateral = white_lateral(dmap.tile_size)
    strips = []
    for lane in dmap.lanes:
        tile = dmap.tile(lane.column, lane.row)
        heading = OPPOSITE[lane.entry]
        closed_right = lane.turn == 0 and RIGHT_OF[heading] not in openings(tile)
        if tile.kind in ("straight", "curve_left", "curve_right") or closed_right:
            strips.append(lane_polyline(lane, lateral, z=MARKING_HEIGHT))
    return strips


def yellow_marking_strips(dmap: DuckietownMap) -> list[np.ndarray]:
    """Dashed yellow centre tape of straights and curves (one dash per strip), drawn along one
    lane of each tile at the road centre line."""
    strips = []
    period = DASH_LENGTH + GAP_LENGTH
    for tile in dmap.road_tiles:
        if tile.kind not in ("straight", "curve_left", "curve_right"):
            continue
        lane = dmap.tile_lanes(tile.column, tile.row)[0]
        for start in np.arange(0.0, lane.length, period):
            stop = min(start + DASH_LENGTH, lane.length)
            strips.append(lane_polyline(lane, -LANE_OFFSET, start, stop, MARKING_HEIGHT))
    return strips


__all__ = ["LANE_HEIGHT", "MARKING_HEIGHT", "lane_centre_strips", "lane_edges", "lane_polyline",
           "white_lateral", "white_marking_strips", "yellow_marking_strips"]
