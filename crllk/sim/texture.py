"""The map's floor texture: road tiles with their markings, decor tiles, drawn in numpy.

Markings follow the Duckietown appearance specification: white solid edge tape 4.8 cm wide
(1.5-6.3 cm from the tile edge), yellow dashed centre tape 2.4 cm wide (5 cm dashes, 2.5 cm
gaps). Curves draw the same bands as arcs about the tile corner. Every texel averages
``supersample``^2 samples so that the texture itself is free of aliasing.
"""

from __future__ import annotations

import functools
import io
import math

import numpy as np
from PIL import Image

from crllk.maps import DuckietownMap, Tile
from crllk.maps.markings import (
    DASH_LENGTH,
    GAP_LENGTH,
    WHITE_INNER,
    WHITE_WIDTH,
    YELLOW_WIDTH,
)
from crllk.maps.road import openings

ROAD_RGB = (75, 72, 69)
WHITE_RGB = (238, 238, 238)
YELLOW_RGB = (238, 225, 77)
DECOR_RGB = {"asphalt": (62, 58, 51), "floor": (149, 154, 82), "grass": (93, 129, 44),
             "calibration_tile": (212, 212, 212), "empty": (30, 30, 34)}
"""Flat colours of the tiles that are not road (the calibration tile: its mean colour, a white
tile with a black checkerboard)."""

PIXELS_PER_TILE = 128
"""Texels along one tile edge (4.6 mm per texel for 0.585 m tiles)."""


def _tile_classes(tile: Tile, u: np.ndarray, v: np.ndarray, s: float) -> np.ndarray:
    """Class of each sample of a road tile: 0 road, 1 white, 2 yellow.

    ``u`` (east) and ``v`` (north) are sample coordinates in metres from the tile centre.
    """
    edges = openings(tile)
    classes = np.zeros(u.shape, dtype=np.uint8)
    if tile.kind == "straight":
        across, along = (u, v) if "N" in edges else (v, u)
        _draw_bands(classes, np.abs(across), along, s, centre_line=True)
    elif tile.kind in ("curve_left", "curve_right"):
        ex, ey = _unit(edges[0])
        ox, oy = _unit(edges[1])
        cu, cv = (ex + ox) * s / 2, (ey + oy) * s / 2
        r = np.hypot(u - cu, v - cv)
        arc = (s / 2) * np.arctan2(np.abs(v - cv), np.abs(u - cu))
        white = ((r >= WHITE_INNER) & (r <= WHITE_INNER + WHITE_WIDTH)) | (
            (r >= s - WHITE_INNER - WHITE_WIDTH) & (r <= s - WHITE_INNER))
        classes[white] = 1
        classes[_yellow(r - s / 2, arc)] = 2
    else:  # intersections: white tape along every closed side
        for edge in "NESW":
            if edge in edges:
                continue
            ex, ey = _unit(edge)
            depth = s / 2 - (u * ex + v * ey)
            classes[(depth >= WHITE_INNER) & (depth <= WHITE_INNER + WHITE_WIDTH)] = 1
    return classes


def _draw_bands(classes: np.ndarray, across: np.ndarray, along: np.ndarray, s: float,
                centre_line: bool) -> None:
    edge_distance = s / 2 - across
    classes[(edge_distance >= WHITE_INNER) & (edge_distance <= WHITE_INNER + WHITE_WIDTH)] = 1
    if centre_line:
        classes[_yellow(across, along)] = 2


def _yellow(offset: np.ndarray, along: np.ndarray) -> np.ndarray:
    period = DASH_LENGTH + GAP_LENGTH
    return (np.abs(offset) <= YELLOW_WIDTH / 2) & (np.mod(along, period) < DASH_LENGTH)


def _unit(edge: str) -> tuple[float, float]:
    return {"N": (0.0, 1.0), "E": (1.0, 0.0), "S": (0.0, -1.0), "W": (-1.0, 0.0)}[edge]


def render_texture(dmap: DuckietownMap, pixels_per_tile: int = PIXELS_PER_TILE,
                   supersample: int = 3) -> np.ndarray:
    """RGB uint8 image of the whole map, row 0 at the north edge, column 0 at the west."""
    return _render_texture(dmap.spec, pixels_per_tile, supersample)


@functools.lru_cache(maxsize=16)
def _render_texture(spec, pixels_per_tile: int, supersample: int) -> np.ndarray:
    s, n, k = spec.tile_size, pixels_per_tile, supersample
    palette = np.array([ROAD_RGB, WHITE_RGB, YELLOW_RGB], dtype=np.float32)
    # Sample offsets within a tile, north-up: rows go south, columns go east.
    fine = (np.arange(n * k) + 0.5) / (n * k) * s - s / 2
    u, v = np.meshgrid(fine, -fine)
    image = np.zeros((spec.rows * n, spec.columns * n, 3), dtype=np.uint8)
    for row in spec.tiles:
        for tile in row:
            if tile.drivable:
                rgb = palette[_tile_classes(tile, u, v, s)]
                block = rgb.reshape(n, k, n, k, 3).mean(axis=(1, 3))
            else:
                block = np.broadcast_to(np.float32(DECOR_RGB[tile.kind]), (n, n, 3))
            image[tile.row * n:(tile.row + 1) * n, tile.column * n:(tile.column + 1) * n] = (
                np.rint(block).astype(np.uint8))
    return image


def texture_png(dmap: DuckietownMap, pixels_per_tile: int = PIXELS_PER_TILE) -> bytes:
    """The map texture encoded as PNG bytes."""
    return _texture_png(dmap.spec, pixels_per_tile)


@functools.lru_cache(maxsize=16)
def _texture_png(spec, pixels_per_tile: int) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(_render_texture(spec, pixels_per_tile, 3)).save(buffer, format="PNG")
    return buffer.getvalue()


def world_to_texel(dmap: DuckietownMap, x: float, y: float,
                   pixels_per_tile: int = PIXELS_PER_TILE) -> tuple[int, int]:
    """(row, column) of the texel under a world point."""
    scale = pixels_per_tile / dmap.tile_size
    return math.floor((dmap.height - y) * scale), math.floor(x * scale)
