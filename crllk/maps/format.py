"""The Duckietown map format: parse and validate a map description.

A map is a grid of tiles (``kind/ORIENT``, row 0 at the north edge), a ``tile_size`` in metres
and optional ``objects`` (a list or a mapping of named objects; :mod:`crllk.maps.objects`).
World frame: x east, y north; tile (column i, row j) of an R-row grid covers x in
[i*s, (i+1)*s] and y in [(R-1-j)*s, (R-j)*s]. Maps beyond :data:`MAX_MAP_SIDE`,
:data:`MAX_MAP_TILES` or :data:`MAX_MAP_OBJECTS` are refused before their tiles and objects are
read.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from crllk.errors import MapError, MapWarning
from crllk.maps.objects import MapObject, parse_objects

HEADINGS = ("N", "E", "S", "W")
"""Compass headings; also the names of a tile's four edges."""

DRIVABLE_KINDS = ("straight", "curve_left", "curve_right", "3way_left", "3way_right", "4way")
INTERSECTION_KINDS = ("3way_left", "3way_right", "4way")
DECOR_KINDS = ("asphalt", "floor", "grass", "calibration_tile")
EMPTY_KIND = "empty"

DEFAULT_ORIENTATION = "E"
"""Orientation of a straight or three-way tile written without one (``straight``,
``3way_left``), as the Duckietown simulator reads it. A four-way tile needs none; a curve must
have one."""

MAX_MAP_TILES = 1024
"""Most tiles (rows x columns) a map may have: 32 x 32, five times the largest Duckietown maps
(about 200 tiles). Building the scene takes time and memory in proportion: about 10 s and
0.5 GB at the limit."""
MAX_MAP_SIDE = 64
"""Most rows, and most columns, a map may have (the longest Duckietown map is 36 tiles)."""
TILE_SIZE_RANGE = (0.3, 3.0)
"""Tile pitches a map may have (m); Duckietown's is 0.585. Below about 0.23 m the inner edge
of a right turn's lane has a negative radius; at 3 m a map of :data:`MAX_MAP_SIDE` tiles
(192 m) still fits the overhead camera's frame (about 240 m)."""
MAX_MAP_OBJECTS = 1000
"""Most objects a map may list (before AprilTags are left out); the largest Duckietown maps
list under 150."""

MAP_KEYS = ("tiles", "tile_size", "objects", "name", "start_tile", "start_pose", "version")
"""Keys a map may have. ``start_tile``, ``start_pose`` and ``version`` are accepted and unused:
episodes start at random road poses. Other keys are ignored with a :class:`MapWarning`."""


@dataclass(frozen=True)
class Tile:
    """One grid cell: ``kind`` and, for road tiles but ``4way``, ``orientation`` (N, E, S or
    W)."""

    kind: str
    orientation: str | None
    column: int
    row: int

    @property
    def drivable(self) -> bool:
        return self.kind in DRIVABLE_KINDS

    @property
    def intersection(self) -> bool:
        """Whether the tile is a three- or four-way intersection (no lane lines inside)."""
        return self.kind in INTERSECTION_KINDS

    @property
    def label(self) -> str:
        return self.kind if self.orientation is None else f"{self.kind}/{self.orientation}"


@dataclass(frozen=True)
class MapSpec:
    """A validated map description, before any lane geometry is built."""

    name: str
    source: str
    tile_size: float
    tiles: tuple[tuple[Tile, ...], ...]
    objects: tuple[MapObject, ...]

    @property
    def rows(self) -> int:
        return len(self.tiles)

    @property
    def columns(self) -> int:
        return len(self.tiles[0])


def parse_map(data: Any, *, name: str, source: str | Path, field_prefix: str = "") -> MapSpec:
    """Validate a map mapping (as read from YAML) and return a :class:`MapSpec`.

    Raises:
        MapError: naming ``source`` and the offending field for any problem.
    """
    source = str(source)
    if not isinstance(data, Mapping):
        raise MapError(source, field_prefix.rstrip(".") or "<top>", "expected a mapping")
    if "tile_size" not in data:
        raise MapError(source, f"{field_prefix}tile_size", "missing (the tile pitch in metres)")
    tile_size = _positive_number(data["tile_size"], source, f"{field_prefix}tile_size")
    if not TILE_SIZE_RANGE[0] <= tile_size <= TILE_SIZE_RANGE[1]:
        raise MapError(source, f"{field_prefix}tile_size", f"must lie in [{TILE_SIZE_RANGE[0]}, "
                       f"{TILE_SIZE_RANGE[1]}] m (Duckietown's is 0.585), got {tile_size:g}")
    _check_limits(data, source, field_prefix)
    tiles = _parse_tiles(data.get("tiles"), source, f"{field_prefix}tiles")
    objects = parse_objects(data.get("objects"), tile_size=tile_size, rows=len(tiles),
                            columns=len(tiles[0]), source=source,
                            field=f"{field_prefix}objects")
    unknown = [str(key) for key in data if key not in MAP_KEYS]
    if unknown:
        warnings.warn(MapWarning(source, ", ".join(field_prefix + key for key in unknown),
                                 "unknown map key" + ("s" if len(unknown) > 1 else "")
                                 + ", ignored"), stacklevel=2)
    return MapSpec(name=name, source=source, tile_size=tile_size, tiles=tiles, objects=objects)


def _check_limits(data: Mapping, source: str, field_prefix: str) -> None:
    """Refuse maps beyond :data:`MAX_MAP_SIDE`, :data:`MAX_MAP_TILES` or
    :data:`MAX_MAP_OBJECTS` before reading their tiles and objects."""
    raw_tiles = data.get("tiles")
    if isinstance(raw_tiles, list):
        lengths = [len(row) if isinstance(row, list) else 1 for row in raw_tiles]
        size = f"{len(lengths)} x {max(lengths, default=0)} (rows x columns)"
        if max([len(lengths), *lengths]) > MAX_MAP_SIDE:
            raise MapError(source, f"{field_prefix}tiles", f"{size}: a map may have at most "
                           f"{MAX_MAP_SIDE} rows and {MAX_MAP_SIDE} columns")
        if sum(lengths) > MAX_MAP_TILES:
            raise MapError(source, f"{field_prefix}tiles", f"{size}, {sum(lengths)} tiles, "
                           f"more than the {MAX_MAP_TILES} a map may have")
    raw_objects = data.get("objects")
    if isinstance(raw_objects, list | Mapping) and len(raw_objects) > MAX_MAP_OBJECTS:
        raise MapError(source, f"{field_prefix}objects", f"{len(raw_objects)} objects, more "
                       f"than the {MAX_MAP_OBJECTS} a map may have")


def _positive_number(value: Any, source: str, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MapError(source, field, f"expected a number, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise MapError(source, field, f"must be a positive number, got {value!r}")
    return float(value)


def _parse_tiles(raw: Any, source: str, field: str) -> tuple[tuple[Tile, ...], ...]:
    if not isinstance(raw, list) or not raw:
        raise MapError(source, field, "missing or empty (a list of tile rows)")
    width = None
    rows = []
    for j, raw_row in enumerate(raw):
        if not isinstance(raw_row, list) or not raw_row:
            raise MapError(source, f"{field}[{j}]", "expected a non-empty list of tiles")
        if width is None:
            width = len(raw_row)
        elif len(raw_row) != width:
            raise MapError(
                source, f"{field}[{j}]", f"ragged rows: {len(raw_row)} tiles, row 0 has {width}"
            )
        rows.append(tuple(_parse_tile(t, i, j, source, f"{field}[{j}][{i}]")
                          for i, t in enumerate(raw_row)))
    return tuple(rows)


def _parse_tile(raw: Any, column: int, row: int, source: str, field: str) -> Tile:
    if not isinstance(raw, str):
        raise MapError(source, field, f"expected a string like 'straight/N', got {raw!r}")
    kind, slash, orientation = raw.strip().partition("/")
    kind, orientation = kind.strip(), orientation.strip()
    known = DRIVABLE_KINDS + DECOR_KINDS + (EMPTY_KIND,)
    if kind not in known:
        raise MapError(source, field, f"unknown tile kind {kind!r} (known: {', '.join(known)})")
    if not slash and kind in ("straight", "3way_left", "3way_right"):
        orientation = DEFAULT_ORIENTATION
    oriented = kind in DRIVABLE_KINDS and kind != "4way"
    if (oriented or orientation) and orientation not in HEADINGS:
        raise MapError(source, field,
                       f"bad orientation {orientation!r} in {raw!r} (use N, E, S or W)")
    return Tile(kind, orientation if oriented else None, column, row)
