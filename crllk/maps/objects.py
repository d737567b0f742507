"""Map objects: kinds, sizes, and where the map file places them.

Four ways of placing an object are read, in this order of precedence:

- ``pos: [x, z]`` in tile units from the north-west corner (x east, z south), with ``rotate``
  in degrees counter-clockwise;
- ``place: {tile: [i, j], relative: {~SE2Transform: {p: [dx, dy], theta_deg}}}``: metres from
  the centre of tile column i, row j counted from the south edge;
- ``attach: {tile: [i, j], slot: k}``: beside the tile corner at column line i, row line j
  (counted from the south-west corner of the map), in one of eight slots around it; the heading
  is ``rotate`` or the ``pose``'s angle;
- ``pose: {~SE2Transform: {p: [x, y], theta_deg}}``: metres from the south-west corner.

World frame: x east, y north from the map's south-west corner; ``yaw`` counter-clockwise from +x.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from crllk.errors import MapError

_SIGN_SIZE = (0.040, 0.051, 0.180)
"""Footprint and height (m) of a traffic sign on its pole."""
SIGN_KINDS = (
    "sign_stop", "sign_yield", "sign_T_intersect", "sign_left_T_intersect",
    "sign_right_T_intersect", "sign_4_way_intersect", "sign_t_light_ahead",
    "sign_duck_crossing", "sign_pedestrian", "sign_parking", "sign_do_not_enter",
    "sign_no_left_turn", "sign_no_right_turn", "sign_oneway_left", "sign_oneway_right",
    "sign_1_way_left", "sign_1_way_right",
)
"""Traffic signs: all the same post with a different face."""

OBJECT_SIZES: dict[str, tuple[float, float, float]] = {
    "duckie": (0.065, 0.045, 0.060),
    "cone": (0.051, 0.051, 0.080),
    "barrier": (0.285, 0.057, 0.080),
    "duckiebot": (0.195, 0.144, 0.120),
    "bus": (0.659, 0.206, 0.180),
    "truck": (0.362, 0.156, 0.200),
    "tree": (0.140, 0.140, 0.250),
    "house": (0.676, 0.879, 0.500),
    "building": (0.640, 0.424, 0.600),
    "trafficlight": (0.124, 0.639, 0.400),
    "checkerboard": (0.170, 0.170, 0.170),
    "sign_blank": (0.057, 0.086, 0.180),
    **dict.fromkeys(SIGN_KINDS, _SIGN_SIZE),
}
"""Footprint length (along the object's heading) x width x height in metres at the reference
height, from the Duckietown object meshes. Other heights scale the whole box proportionally."""

NON_COLLIDING_KINDS = ("trafficlight",)
"""Kinds drawn but never collided with: the traffic light's arm reaches over the
intersection above the robots."""
SKIPPED_KINDS = ("floor_tag",)
"""Kinds read and left out: flat AprilTags on the floor, neither drawn nor collided with."""

_SLOT_LONG, _SLOT_SHORT = 0.09, 0.035
"""Offsets (tile units) of an attached object from its tile corner, along and across."""
_SLOTS = {0: (_SLOT_LONG, _SLOT_SHORT), 1: (_SLOT_SHORT, _SLOT_LONG),
          2: (-_SLOT_SHORT, _SLOT_LONG), 3: (-_SLOT_LONG, _SLOT_SHORT),
          4: (-_SLOT_LONG, -_SLOT_SHORT), 5: (-_SLOT_SHORT, -_SLOT_LONG),
          6: (_SLOT_SHORT, -_SLOT_LONG), 7: (_SLOT_LONG, -_SLOT_SHORT)}
"""The eight slots around a tile corner, counter-clockwise from east (tile units)."""


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

    @property
    def collidable(self) -> bool:
        """Whether the robot collides with it (every kind but :data:`NON_COLLIDING_KINDS`)."""
        return self.kind not in NON_COLLIDING_KINDS


@dataclass(frozen=True)
class _Grid:
    """What object placement needs to know of the map."""

    tile_size: float
    rows: int
    columns: int
    source: str


def parse_objects(raw: Any, *, tile_size: float, rows: int, columns: int, source: str,
                  field: str) -> tuple[MapObject, ...]:
    """The objects of a map: ``raw`` is a list of objects, a mapping of named objects or None.
    Objects of :data:`SKIPPED_KINDS` are left out.

    Raises:
        MapError: naming ``source`` and the object's field for any problem.
    """
    if raw is None:
        return ()
    if isinstance(raw, list):
        entries = [(f"{field}[{k}]", obj) for k, obj in enumerate(raw)]
    elif isinstance(raw, Mapping):
        entries = [(f"{field}.{name}", obj) for name, obj in raw.items()]
    else:
        raise MapError(source, field, "expected a list of objects or a mapping of named objects")
    grid = _Grid(tile_size, rows, columns, source)
    objects = (_parse_object(obj, grid, where) for where, obj in entries)
    return tuple(obj for obj in objects if obj is not None)


def _parse_object(raw: Any, grid: _Grid, field: str) -> MapObject | None:
    source = grid.source
    if not isinstance(raw, Mapping):
        raise MapError(source, field, "expected a mapping with kind and pos")
    kind = raw.get("kind")
    if isinstance(kind, str) and kind in SKIPPED_KINDS:
        return None
    if not isinstance(kind, str) or kind not in OBJECT_SIZES:
        raise MapError(source, f"{field}.kind",
                       f"unknown object kind {kind!r} (known: {', '.join(OBJECT_SIZES)})")
    x, y, yaw = _placement(raw, grid, field)
    length, width, height = OBJECT_SIZES[kind]
    if "height" in raw:
        scale = _positive(raw["height"], source, f"{field}.height") / height
    elif "scale" in raw:
        scale = _positive(raw["scale"], source, f"{field}.scale")
    else:
        scale = 1.0
    for flag in ("static", "optional"):
        if flag in raw and not isinstance(raw[flag], bool):
            raise MapError(source, f"{field}.{flag}", f"expected true or false, got {raw[flag]!r}")
    return MapObject(kind=kind, x=x, y=y, yaw=yaw, length=length * scale, width=width * scale,
                     height=height * scale, static=raw.get("static", True),
                     optional=raw.get("optional", False))


def _placement(raw: Mapping, grid: _Grid, field: str) -> tuple[float, float, float]:
    """World (x, y, yaw) of an object from whichever placement it has."""
    s, source = grid.tile_size, grid.source
    if "pos" in raw or not any(key in raw for key in ("place", "attach", "pose")):
        px, pz = _pair(raw.get("pos"), source, f"{field}.pos", "[x, z] in tile units")
        if not (0.0 <= px <= grid.columns and 0.0 <= pz <= grid.rows):
            raise MapError(source, f"{field}.pos", f"{[px, pz]} is off the map (x in "
                           f"[0, {grid.columns}], z in [0, {grid.rows}] tile units)")
        return px * s, (grid.rows - pz) * s, _rotate(raw, source, field)
    if "place" in raw:
        place = _mapping(raw["place"], source, f"{field}.place")
        column, row = _tile(place.get("tile"), grid, f"{field}.place.tile", corner=False)
        dx, dy, yaw = _transform(place.get("relative"), source, f"{field}.place.relative")
        x, y = (column + 0.5) * s + dx, (row + 0.5) * s + dy
    elif "attach" in raw:
        attach = _mapping(raw["attach"], source, f"{field}.attach")
        column, row = _tile(attach.get("tile"), grid, f"{field}.attach.tile", corner=True)
        slot = attach.get("slot")
        if isinstance(slot, bool) or slot not in _SLOTS:
            raise MapError(source, f"{field}.attach.slot",
                           f"expected a slot number 0 to 7, got {slot!r}")
        sx, sy = _SLOTS[slot]
        x, y = (column + sx) * s, (row + sy) * s
        if "rotate" in raw or "pose" not in raw:
            yaw = _rotate(raw, source, field)
        else:
            yaw = _transform(raw["pose"], source, f"{field}.pose")[2]
        return x, y, yaw
    else:
        x, y, yaw = _transform(raw["pose"], source, f"{field}.pose")
    if not (0.0 <= x <= grid.columns * s and 0.0 <= y <= grid.rows * s):
        raise MapError(source, field, f"its position ({x:.3f}, {y:.3f}) m is off the map")
    return x, y, yaw


def _rotate(raw: Mapping, source: str, field: str) -> float:
    rotate = raw.get("rotate", 0.0)
    if isinstance(rotate, bool) or not isinstance(rotate, int | float) or not math.isfinite(
            rotate):
        raise MapError(source, f"{field}.rotate", f"expected degrees, got {rotate!r}")
    return math.radians(float(rotate))


def _transform(raw: Any, source: str, field: str) -> tuple[float, float, float]:
    """(x, y, theta) of a ``{~SE2Transform: {p: [x, y], theta_deg | theta}}`` (m, rad); a
    missing ``p`` or angle is zero."""
    outer = _mapping(raw, source, field)
    inner = outer.get("~SE2Transform", {}) if "~SE2Transform" in outer else outer
    inner = _mapping(inner if inner is not None else {}, source, field)
    x, y = _pair(inner.get("p", [0.0, 0.0]), source, f"{field}.p", "[x, y] in metres")
    if "theta" in inner:
        theta = _number(inner["theta"], source, f"{field}.theta")
    else:
        theta = math.radians(_number(inner.get("theta_deg", 0.0), source, f"{field}.theta_deg"))
    return x, y, theta


def _tile(raw: Any, grid: _Grid, field: str, *, corner: bool) -> tuple[int, int]:
    """(column, row from the south) of a tile, or of a tile corner line with ``corner``."""
    if (not isinstance(raw, list | tuple) or len(raw) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in raw)):
        raise MapError(grid.source, field, f"expected [column, row] integers, got {raw!r}")
    extra = 1 if corner else 0
    column, row = raw
    if not (0 <= column < grid.columns + extra and 0 <= row < grid.rows + extra):
        raise MapError(grid.source, field, f"{list(raw)} is off the map ({grid.columns} "
                       f"columns, {grid.rows} rows)")
    return column, row


def _pair(raw: Any, source: str, field: str, what: str) -> tuple[float, float]:
    if (not isinstance(raw, list | tuple) or len(raw) != 2
            or not all(isinstance(p, int | float) and not isinstance(p, bool)
                       and math.isfinite(p) for p in raw)):
        raise MapError(source, field, f"expected {what}, got {raw!r}")
    return float(raw[0]), float(raw[1])


def _mapping(raw: Any, source: str, field: str) -> Mapping:
    if not isinstance(raw, Mapping):
        raise MapError(source, field, f"expected a mapping, got {raw!r}")
    return raw


def _number(value: Any, source: str, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise MapError(source, field, f"expected a number, got {value!r}")
    return float(value)


def _positive(value: Any, source: str, field: str) -> float:
    number = _number(value, source, field)
    if number <= 0:
        raise MapError(source, field, f"must be a positive number, got {value!r}")
    return number
