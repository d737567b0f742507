"""The Duckietown map format: parse and validate a map description.

A map is a grid of tiles (``kind/ORIENT``, row 0 at the north edge), a ``tile_size`` in metres
and optional ``objects``. World frame: x east, y north; tile (column i, row j) of an R-row grid
covers x in [i*s, (i+1)*s] and y in [(R-1-j)*s, (R-j)*s].
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from crllk.errors import MapError

HEADINGS = ("N", "E", "S", "W")
"""Compass headings; also the names of a tile's four edges."""

DRIVABLE_KINDS = ("straight", "curve_left", "curve_right", "3way_left", "3way_right", "4way")
DECOR_KINDS = ("asphalt", "floor", "grass")
EMPTY_KIND = "empty"

# Footprint length (along the object's heading) x width x height in metres at the reference
# height, from the Duckietown object table. Other heights scale the whole box proportionally.
OBJECT_SIZES: dict[str, tuple[float, float, float]] = {
    "duckie": (0.065, 0.045, 0.060),
    "cone": (0.051, 0.051, 0.080),
    "barrier": (0.285, 0.057, 0.080),
    "duckiebot": (0.195, 0.144, 0.120),
    "bus": (0.659, 0.206, 0.180),
    "truck": (0.362, 0.156, 0.200),
    "tree": (0.140, 0.140, 0.250),
    "sign_blank": (0.057, 0.086, 0.180),
}


@dataclass(frozen=True)
class Tile:
    """One grid cell: ``kind`` and, for road tiles, ``orientation`` (N, E, S or W)."""

    kind: str
    orientation: str | None
    column: int
    row: int

    @property
    def drivable(self) -> bool:
        return self.kind in DRIVABLE_KINDS

    @property
    def label(self) -> str:
        return self.kind if self.orientation is None else f"{self.kind}/{self.orientation}"


@dataclass(frozen=True)
class MapObject:
    """A static object; position and size in metres, ``yaw`` in radians (CCW from +x)."""

    kind: str
    x: float
    y: float
    yaw: float
    length: float
    width: float
    height: float
    static: bool = True
    optional: bool = False


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
    tiles = _parse_tiles(data.get("tiles"), source, f"{field_prefix}tiles")
    rows, columns = len(tiles), len(tiles[0])
    raw_objects = data.get("objects") or []
    if not isinstance(raw_objects, list):
        raise MapError(source, f"{field_prefix}objects", "expected a list of objects")
    objects = tuple(
        _parse_object(obj, tile_size, rows, columns, source, f"{field_prefix}objects[{k}]")
        for k, obj in enumerate(raw_objects)
    )
    unknown = set(data) - {"tiles", "tile_size", "objects", "start_tile", "name"}
    if unknown:
        raise MapError(source, f"{field_prefix}{sorted(unknown, key=str)[0]}", "unknown key")
    return MapSpec(name=name, source=source, tile_size=tile_size, tiles=tiles, objects=objects)


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
    kind, _, orientation = raw.strip().partition("/")
    known = DRIVABLE_KINDS + DECOR_KINDS + (EMPTY_KIND,)
    if kind not in known:
        raise MapError(source, field, f"unknown tile kind {kind!r} (known: {', '.join(known)})")
    if kind in DRIVABLE_KINDS:
        if orientation not in HEADINGS:
            raise MapError(
                source, field, f"bad orientation {orientation!r} in {raw!r} (use N, E, S or W)"
            )
        return Tile(kind, orientation, column, row)
    if orientation and orientation not in HEADINGS:
        raise MapError(source, field, f"bad orientation {orientation!r} in {raw!r}")
    return Tile(kind, None, column, row)


def _parse_object(
    raw: Any, tile_size: float, rows: int, columns: int, source: str, field: str
) -> MapObject:
    if not isinstance(raw, Mapping):
        raise MapError(source, field, "expected a mapping with kind and pos")
    kind = raw.get("kind")
    if not isinstance(kind, str) or kind not in OBJECT_SIZES:
        raise MapError(
            source, f"{field}.kind",
            f"unknown object kind {kind!r} (known: {', '.join(OBJECT_SIZES)})",
        )
    pos = raw.get("pos")
    if (not isinstance(pos, list | tuple) or len(pos) != 2
            or not all(isinstance(p, int | float) and not isinstance(p, bool) for p in pos)):
        raise MapError(source, f"{field}.pos", f"expected [x, z] in tile units, got {pos!r}")
    px, pz = float(pos[0]), float(pos[1])
    if not (0.0 <= px <= columns and 0.0 <= pz <= rows):
        raise MapError(
            source, f"{field}.pos",
            f"{[px, pz]} is off the map (x in [0, {columns}], z in [0, {rows}] tile units)",
        )
    rotate = raw.get("rotate", 0.0)
    if (isinstance(rotate, bool) or not isinstance(rotate, int | float)
            or not math.isfinite(rotate)):
        raise MapError(source, f"{field}.rotate", f"expected degrees, got {rotate!r}")
    length, width, height = OBJECT_SIZES[kind]
    if "height" in raw:
        scale = _positive_number(raw["height"], source, f"{field}.height") / height
    elif "scale" in raw:
        scale = _positive_number(raw["scale"], source, f"{field}.scale")
    else:
        scale = 1.0
    for flag in ("static", "optional"):
        if flag in raw and not isinstance(raw[flag], bool):
            raise MapError(source, f"{field}.{flag}", f"expected true or false, got {raw[flag]!r}")
    return MapObject(
        kind=kind,
        x=px * tile_size,
        y=(rows - pz) * tile_size,
        yaw=math.radians(float(rotate)),
        length=length * scale,
        width=width * scale,
        height=height * scale,
        static=raw.get("static", True),
        optional=raw.get("optional", False),
    )
