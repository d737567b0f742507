"""The ``traffic`` task setting: other Duckiebots on the lanes and duckies crossing the road.

    traffic:
      vehicles:
        ahead: 1                 # in the robot's lane, ahead of it
        opposite: 1              # in the other lane, coming towards it
        distance: [0.8, 2.0]     # m along the lanes from the robot, drawn per vehicle
        speed: [0.1, 0.2]        # m/s, drawn per vehicle and episode
      pedestrians:
        crossings: [[3, 1]]      # straight road tiles [column, row], one duckie each
        speed: [0.08, 0.15]      # m/s, drawn per crossing
        wait: [0.5, 6.0]         # s at the roadside before each crossing
      headway: 0.3               # m: the headway signal's bound

Every value is checked; a bad one raises :class:`~crllk.errors.ConfigError` naming the file and
the field. Movers do not avoid static obstacles, so traffic needs a road without any.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from crllk.errors import ConfigError
from crllk.maps import DuckietownMap
from crllk.maps.obstacles import ObstacleIndex
from crllk.maps.routes import crossing

Range = tuple[float, float]

MIN_VEHICLE_DISTANCE = 0.4
"""Least distance (m) along the lanes between the robot's start and a vehicle's."""
START_SPACING = 0.33
"""Least distance (m) between the start positions of two vehicles in one lane: a Duckiebot's
length (0.18 m) and 0.15 m."""


@dataclass(frozen=True)
class VehiclesConfig:
    """Duckiebots driven along the lanes."""

    ahead: int = 0
    """Vehicles in the robot's start lane, ahead of it."""
    opposite: int = 0
    """Vehicles in the lane of the other travel direction."""
    distance: Range = (0.8, 2.0)
    """Range of each vehicle's start distance (m) along the lanes from the robot's."""
    speed: Range = (0.1, 0.2)
    """Range of each vehicle's cruising speed (m/s), drawn per episode."""

    @property
    def count(self) -> int:
        return self.ahead + self.opposite


@dataclass(frozen=True)
class PedestriansConfig:
    """Duckies crossing the road, one per crossing, again and again."""

    crossings: tuple[tuple[int, int], ...] = ()
    """Straight road tiles (column, row) crossed through their centre."""
    speed: Range = (0.08, 0.15)
    """Range of the walking speed (m/s), drawn per crossing."""
    wait: Range = (0.5, 6.0)
    """Range of the time (s) a duckie stands at the roadside before each crossing."""

    @property
    def count(self) -> int:
        return len(self.crossings)


@dataclass(frozen=True)
class TrafficConfig:
    """Moving agents of a task."""

    vehicles: VehiclesConfig = VehiclesConfig()
    pedestrians: PedestriansConfig = PedestriansConfig()
    headway: float = 0.3
    """The headway signal is 1 on steps whose gap (m) from the robot's front to the nearest
    vehicle ahead in its lane is below this."""


_SECTIONS = ("vehicles", "pedestrians", "headway")


def parse_traffic(value: Any, source: str | Path, dmap: DuckietownMap) -> TrafficConfig | None:
    """The task's ``traffic`` setting checked against its map (None: no traffic)."""
    if value is None or value == "none":
        return None
    where = "traffic"
    mapping = _mapping(value, source, where, _SECTIONS)
    vehicles = _vehicles(mapping.get("vehicles", {}), source)
    pedestrians = _pedestrians(mapping.get("pedestrians", {}), source, dmap)
    headway = _number(mapping.get("headway", TrafficConfig.headway), source, "traffic.headway")
    if headway <= 0:
        raise ConfigError(source, "traffic.headway", f"must be positive, got {headway}")
    config = TrafficConfig(vehicles, pedestrians, headway)
    blocking = ObstacleIndex(dmap).on_road
    if blocking and vehicles.count + pedestrians.count:
        raise ConfigError(source, where, f"movers do not avoid obstacles, and objects "
                          f"{list(blocking)} of the map stand on the road")
    return config


def _vehicles(value: Any, source: str | Path) -> VehiclesConfig:
    where = "traffic.vehicles"
    mapping = _mapping(value, source, where, ("ahead", "opposite", "distance", "speed"))
    default = VehiclesConfig()
    config = VehiclesConfig(
        ahead=_count(mapping.get("ahead", default.ahead), source, f"{where}.ahead"),
        opposite=_count(mapping.get("opposite", default.opposite), source, f"{where}.opposite"),
        distance=_range(mapping.get("distance", default.distance), source, f"{where}.distance"),
        speed=_range(mapping.get("speed", default.speed), source, f"{where}.speed"))
    if config.distance[0] < MIN_VEHICLE_DISTANCE:
        raise ConfigError(source, f"{where}.distance", f"must start at least "
                          f"{MIN_VEHICLE_DISTANCE} m from the robot, got {list(config.distance)}")
    crowded = max(config.ahead, config.opposite)
    if (crowded - 1) * START_SPACING > config.distance[1] - config.distance[0]:
        raise ConfigError(source, f"{where}.distance", f"{crowded} vehicles in one lane start "
                          f"{START_SPACING} m apart: the range {list(config.distance)} is too "
                          "short")
    return config


def _pedestrians(value: Any, source: str | Path, dmap: DuckietownMap) -> PedestriansConfig:
    where = "traffic.pedestrians"
    mapping = _mapping(value, source, where, ("crossings", "speed", "wait"))
    default = PedestriansConfig()
    tiles = mapping.get("crossings", [])
    if not isinstance(tiles, list | tuple):
        raise ConfigError(source, f"{where}.crossings",
                          f"expected a list of [column, row], got {tiles!r}")
    crossings = []
    for k, tile in enumerate(tiles):
        field = f"{where}.crossings[{k}]"
        if not (isinstance(tile, list | tuple) and len(tile) == 2
                and all(isinstance(v, int) and not isinstance(v, bool) for v in tile)):
            raise ConfigError(source, field, f"expected [column, row], got {tile!r}")
        try:
            crossing(dmap, tile[0], tile[1], 0.0)
        except ValueError as err:
            raise ConfigError(source, field, str(err)) from None
        crossings.append((tile[0], tile[1]))
    if len(set(crossings)) != len(crossings):
        raise ConfigError(source, f"{where}.crossings", "a tile appears twice")
    return PedestriansConfig(
        tuple(crossings),
        speed=_range(mapping.get("speed", default.speed), source, f"{where}.speed"),
        wait=_range(mapping.get("wait", default.wait), source, f"{where}.wait"))


def _mapping(value: Any, source: str | Path, where: str, known: tuple[str, ...]) -> Mapping:
    if not isinstance(value, Mapping):
        raise ConfigError(source, where, f"expected a mapping, got {value!r}")
    for key in value:
        if key not in known:
            raise ConfigError(source, f"{where}.{key}",
                              f"unknown setting (known: {', '.join(known)})")
    return value


def _count(value: Any, source: str | Path, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ConfigError(source, where, f"expected a whole number >= 0, got {value!r}")
    return value


def _number(value: Any, source: str | Path, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(source, where, f"expected a finite number, got {value!r}")
    return float(value)


def _range(value: Any, source: str | Path, where: str) -> Range:
    """A range [low, high] of positive numbers."""
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ConfigError(source, where, f"expected [low, high], got {value!r}")
    low, high = (_number(v, source, where) for v in value)
    if low <= 0 or low > high:
        raise ConfigError(source, where, f"expected 0 < low <= high, got {list(value)}")
    return (low, high)


__all__ = ["MIN_VEHICLE_DISTANCE", "START_SPACING", "PedestriansConfig", "TrafficConfig",
           "VehiclesConfig", "parse_traffic"]
