"""Task settings: a map plus spawn, episode, motor and camera settings, read from YAML.

A task file (``tasks/<name>.yaml``) holds ``map:`` (a Duckietown map) and any of the sections
below; a bare Duckietown map file is a task with default settings. Every value is checked and a
bad one raises :class:`~crllk.errors.ConfigError` naming the file and the field.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from crllk.errors import ConfigError
from crllk.maps import DuckietownMap, load_map
from crllk.paths import task_file, task_name_problem, task_names
from crllk.sim.constants import PHYSICS_TIMESTEP
from crllk.sim.motor import MotorConfig
from crllk.tasks.constraints import AGGREGATES, BUILTIN, DEFAULT, SIGNALS, Constraint
from crllk.tasks.randomization import RandomizeConfig, parse_randomize
from crllk.tasks.traffic_config import TrafficConfig, parse_traffic
from crllk.yaml_files import read_yaml


@dataclass(frozen=True)
class SpawnConfig:
    """Where episodes start: a random drivable tile and direction, near the lane centre."""

    lateral_offset: tuple[float, float] = (-0.04, 0.04)
    """Range of the start's offset from the lane centre (m)."""
    heading_error: tuple[float, float] = (-0.25, 0.25)
    """Range of the start's heading error (rad)."""
    obstacle_clearance: float = 0.25
    """Least distance between the robot's footprint and any obstacle's footprint (m)."""
    encounters: float = 0.0
    """Probability that an episode starts in front of an obstacle that blocks its lane
    (trainers raise it to meet obstacles more often; evaluation keeps the task's own)."""
    encounter_distance: tuple[float, float] = (0.3, 1.2)
    """Range of the distance (m) along the lane from such a start to the obstacle."""
    encounter_lateral_offset: tuple[float, float] = (-0.25, 0.04)
    """Range of such a start's offset from the lane centre (m, positive right): wider than
    ``lateral_offset``, so that some starts are already beside the obstacle's left side."""
    encounter_curve_weight: float = 1.0
    """How much likelier such a start is before a blocking obstacle on a lane that turns (a
    curve, or a turn through an intersection) than before one on a straight lane (1: every
    blocking obstacle alike)."""
    encounter_horizon: int = 0
    """Control steps after which an episode that started in front of an obstacle is truncated
    (a positive number; unset, 0: the task's ``horizon``), so that training frames go to
    passing obstacles. Applies to the batched environment (:mod:`crllk.envs.batched`)."""


@dataclass(frozen=True)
class CameraConfig:
    """The robot camera as the policy sees it."""

    height: int = 30
    width: int = 40
    supersample: int = 2
    """Render this many times larger along each axis and average down (anti-aliasing)."""
    robot_frames: bool = False
    """Take each image as the robot does instead: a 640x480 frame, JPEG-encoded, prepared as
    the pilot prepares camera frames (:func:`crllk.tasks.frames.robot_camera_image`). Slower;
    for evaluating how a policy takes the deployment path."""


@dataclass(frozen=True)
class TaskConfig:
    """Everything that defines a lane-keeping task."""

    name: str
    map: DuckietownMap
    source: str
    horizon: int = 512
    """Control steps per episode (a time limit: truncation, not termination)."""
    control_rate: float = 30.0
    """Control frequency (Hz)."""
    off_road_lane_cost: float = 10.0
    """Lane cost when off the road (dm)."""
    spawn: SpawnConfig = field(default_factory=SpawnConfig)
    motor: MotorConfig = field(default_factory=MotorConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    constraints: tuple[Constraint, ...] = tuple(BUILTIN[name] for name in DEFAULT)
    """What the task constrains (:mod:`crllk.tasks.constraints`); its costs, in this order."""
    randomize: RandomizeConfig | None = None
    """Per-episode domain randomisation (:mod:`crllk.tasks.randomization`); None: off."""
    traffic: TrafficConfig | None = None
    """Other Duckiebots and duckie pedestrians (:mod:`crllk.tasks.traffic_config`); None:
    none."""

    @property
    def control_timestep(self) -> float:
        """Seconds per control step."""
        return 1.0 / self.control_rate

    def step_limit(self, encounter: bool = False) -> int:
        """The time limit (control steps) after which an episode is truncated: ``horizon``, or
        ``spawn.encounter_horizon`` (when set and shorter) for an episode that started in
        front of an obstacle. The one definition both environments use."""
        short = self.spawn.encounter_horizon
        return min(short, self.horizon) if encounter and short else self.horizon


_PHYSICS_RATE = 1.0 / PHYSICS_TIMESTEP
"""Physics steps per second (Hz)."""

_SECTIONS = {"spawn": SpawnConfig, "motor": MotorConfig, "camera": CameraConfig}
_SCALARS = ("horizon", "control_rate", "off_road_lane_cost")


def load_task_config(task: str | Path, overrides: Mapping[str, Any] | None = None) -> TaskConfig:
    """Read a task by name (a file in ``tasks/``) or by path (a task or map file).

    ``overrides`` replaces settings, e.g. ``{"motor": {"delay": 0.0}, "horizon": 64}``.
    """
    path = Path(task)
    if path.suffix not in (".yaml", ".yml"):
        path = task_file(str(task))
        if not path.exists():
            raise ConfigError(task, "task", f"unknown task (known: {', '.join(task_names())}; "
                              "or give the path of a task or map file)")
    elif not path.exists():
        raise ConfigError(path, "<file>", "no such file")
    data = read_yaml(path)
    if not isinstance(data, Mapping):
        raise ConfigError(path, "<top>", "expected a mapping")
    settings = dict(data) if "map" in data else {}
    settings = _merge(settings, dict(overrides or {}))
    dmap = load_map(path)
    return parse_task(settings, name=str(settings.pop("name", path.stem)), dmap=dmap, source=path)


def parse_task(settings: Mapping[str, Any], *, name: str, dmap: DuckietownMap,
               source: str | Path) -> TaskConfig:
    """Check task settings (all sections but ``map``) and build the :class:`TaskConfig`."""
    problem = task_name_problem(name)
    if problem:
        raise ConfigError(source, "name", problem)
    kwargs: dict[str, Any] = {}
    for key, value in settings.items():
        if key == "map":
            continue
        if key in _SECTIONS:
            kwargs[key] = _parse_section(_SECTIONS[key], value, source, key)
        elif key == "constraints":
            kwargs[key] = parse_constraints(value, source)
        elif key == "randomize":
            kwargs[key] = parse_randomize(value, source)
        elif key == "traffic":
            kwargs[key] = parse_traffic(value, source, dmap)
        elif key in _SCALARS:
            kwargs[key] = _check_value(TaskConfig, key, value, source, key)
        else:
            known = (*_SCALARS, *_SECTIONS, "constraints", "randomize", "traffic")
            raise ConfigError(source, key, f"unknown setting (known: map, {', '.join(known)})")
    config = TaskConfig(name=name, map=dmap, source=str(source), **kwargs)
    if config.horizon <= 0:
        raise ConfigError(source, "horizon", f"must be positive, got {config.horizon}")
    if config.control_rate <= 0:
        raise ConfigError(source, "control_rate", f"must be positive, got {config.control_rate}")
    if config.spawn.encounters > 1:
        raise ConfigError(source, "spawn.encounters",
                          f"is a probability and must lie in [0, 1], got {config.spawn.encounters}")
    if not config.spawn.encounter_curve_weight > 0:
        raise ConfigError(source, "spawn.encounter_curve_weight",
                          f"must be positive, got {config.spawn.encounter_curve_weight}")
    if config.spawn.encounter_distance[0] < 0:
        raise ConfigError(source, "spawn.encounter_distance",
                          f"must be non-negative, got {list(config.spawn.encounter_distance)}")
    for k, constraint in enumerate(config.constraints):
        if constraint.signal == "headway" and not (config.traffic
                                                   and config.traffic.vehicles.count):
            raise ConfigError(source, f"constraints[{k}]", f"{constraint.name!r} measures the "
                              "headway to vehicles: declare traffic.vehicles")
    substeps = _PHYSICS_RATE / config.control_rate
    if abs(substeps - round(substeps)) > 1e-9:
        raise ConfigError(source, "control_rate",
                          f"{config.control_rate:g} Hz does not divide the {_PHYSICS_RATE:g} Hz "
                          "physics rate (use e.g. 10, 15, 20, 30, 40, 60)")
    return config


def parse_constraints(value: Any, source: str | Path) -> tuple[Constraint, ...]:
    """A task's ``constraints``: a list whose entries name a built-in constraint (``lane``,
    ``collision``, ``crossing``, ``headway``) or spell one out as a mapping with ``name``,
    ``signal``, ``aggregate``, ``unit`` and ``metric``."""
    if not isinstance(value, list | tuple) or not value:
        raise ConfigError(source, "constraints", f"expected a non-empty list, got {value!r}")
    out: list[Constraint] = []
    for k, entry in enumerate(value):
        where = f"constraints[{k}]"
        if isinstance(entry, str):
            if entry not in BUILTIN:
                raise ConfigError(source, where, f"unknown constraint {entry!r} (known: "
                                  f"{', '.join(BUILTIN)}; or a mapping with "
                                  f"{', '.join(f.name for f in dataclasses.fields(Constraint))})")
            out.append(BUILTIN[entry])
            continue
        if not isinstance(entry, Mapping):
            raise ConfigError(source, where, f"expected a name or a mapping, got {entry!r}")
        fields = [f.name for f in dataclasses.fields(Constraint)]
        unknown = sorted(set(entry) - set(fields))
        missing = [f for f in fields if f not in entry]
        if unknown or missing:
            problem = f"unknown keys {unknown}" if unknown else f"missing keys {missing}"
            raise ConfigError(source, where, f"{problem} (a constraint has {', '.join(fields)})")
        if not all(isinstance(entry[f], str) and entry[f] for f in fields):
            raise ConfigError(source, where, "every key needs a non-empty string")
        if entry["signal"] not in SIGNALS:
            raise ConfigError(source, f"{where}.signal", f"unknown signal {entry['signal']!r} "
                              f"(known: {', '.join(SIGNALS)})")
        if entry["aggregate"] not in AGGREGATES:
            raise ConfigError(source, f"{where}.aggregate", f"must be one of "
                              f"{', '.join(AGGREGATES)}, got {entry['aggregate']!r}")
        out.append(Constraint(**{f: entry[f] for f in fields}))
    seen: set[str] = set()
    for k, constraint in enumerate(out):
        if not constraint.name.isidentifier():
            raise ConfigError(source, f"constraints[{k}].name",
                              f"must be an identifier, got {constraint.name!r}")
        if constraint.name in seen:
            raise ConfigError(source, f"constraints[{k}]", f"{constraint.name!r} appears twice")
        seen.add(constraint.name)
    return tuple(out)


def _merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in overrides.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merge(dict(out[key]), dict(value))
        else:
            out[key] = value
    return out


def _parse_section(cls: type, value: Any, source: str | Path, where: str) -> Any:
    if not isinstance(value, Mapping):
        raise ConfigError(source, where, f"expected a mapping, got {value!r}")
    names = {f.name for f in dataclasses.fields(cls)}
    for key in value:
        if key not in names:
            raise ConfigError(source, f"{where}.{key}",
                              f"unknown setting (known: {', '.join(sorted(names))})")
    return cls(**{k: _check_value(cls, k, v, source, f"{where}.{k}") for k, v in value.items()})


def _check_value(cls: type, name: str, value: Any, source: str | Path, where: str) -> Any:
    hint = typing.get_type_hints(cls)[name]
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(source, where, f"expected a whole number, got {value!r}")
        if value <= 0:
            raise ConfigError(source, where, f"must be positive, got {value}")
        return value
    if hint is float:
        return _number(value, source, where, allow_negative=False)
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(source, where, f"expected true or false, got {value!r}")
        return value
    if typing.get_origin(hint) is tuple:
        if not isinstance(value, list | tuple) or len(value) != 2:
            raise ConfigError(source, where, f"expected [low, high], got {value!r}")
        low, high = (_number(v, source, where, allow_negative=True) for v in value)
        if low > high:
            raise ConfigError(source, where, f"low {low} is above high {high}")
        return (low, high)
    raise TypeError(f"unsupported setting type {hint!r}")  # pragma: no cover


def _number(value: Any, source: str | Path, where: str, *, allow_negative: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(source, where, f"expected a number, got {value!r}")
    if not math.isfinite(value) or (value < 0 and not allow_negative):
        raise ConfigError(source, where, f"must be a finite non-negative number, got {value!r}")
    return float(value)


__all__ = ["CameraConfig", "MotorConfig", "SpawnConfig", "TaskConfig", "load_task_config",
           "parse_constraints", "parse_task"]
