"""Per-episode domain randomisation: the ``randomize`` task setting, its presets and the draws.

``randomize`` is absent or ``none`` (off), a preset name (``default``), or a mapping of any
fields of :class:`RandomizeConfig` (a range ``[low, high]``, or ``null`` for off), optionally
on top of a preset: ``{preset: default, camera_pitch: [0.9, 1.1]}``. Each episode draws one
:class:`~crllk.sim.variation.SceneVariation` from the task's seeded generator, in a fixed
order and only for the fields that are set, so the same seed gives the same episodes and a
task without randomisation draws exactly what it drew before.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from crllk.errors import ConfigError
from crllk.sim import constants as C
from crllk.sim.motor import MotorConfig
from crllk.sim.variation import SceneVariation

Range = tuple[float, float]


@dataclass(frozen=True)
class RandomizeConfig:
    """What each episode draws. Ranges are uniform; None: not randomised."""

    light_intensity: Range | None = None
    """Multiplier of the sun's brightness."""
    light_tilt: Range | None = None
    """Angle of the sun from the vertical (rad); its azimuth is uniform around the circle."""
    ambient: Range | None = None
    """Multiplier of the ambient light."""
    headlight: Range | None = None
    """Multiplier of the headlight (diffuse light from the camera)."""
    floor_color: Range | None = None
    """Multiplier of each RGB channel of the floor: tiles and markings."""
    horizon_color: Range | None = None
    """Multiplier of each RGB channel of the ground beyond the map."""
    object_color: Range | None = None
    """Multiplier of each RGB channel of each map object."""
    camera_height: Range | None = None
    """Multiplier of the camera's height above the floor (0.108 m)."""
    camera_pitch: Range | None = None
    """Multiplier of the camera's pitch below the horizontal (19.15 degrees)."""
    camera_fov: Range | None = None
    """Multiplier of the camera's vertical field of view (75 degrees)."""
    camera_position_noise: float = 0.0
    """Half-width (m) of the uniform noise added to the camera's position along each axis."""
    jpeg_quality: Range | None = None
    """JPEG quality (whole numbers, 1-100) of the camera images."""
    sensor_noise: Range | None = None
    """Standard deviation of the Gaussian sensor noise of each pixel and frame (levels of
    255); drawn per episode."""
    max_speed: Range | None = None
    """Multiplier of the motors' full-duty speed."""
    yaw_rate: Range | None = None
    """Multiplier of the motors' yaw rate per unit duty difference."""
    wheel_distance: Range | None = None
    """Multiplier of the distance between the wheels: the yaw rate per duty divides by it
    (the same wheel speeds turn a wider robot more slowly)."""
    time_constants: Range | None = None
    """Multiplier of both motor time constants."""
    delay: Range | None = None
    """Added to the command delay (s); the sum is at least 0."""
    trim: float = 0.0
    """Standard deviation of the left/right motor asymmetry: the right duty is scaled by
    (1 + trim), the left by (1 - trim)."""
    distractors: int = 0
    """Flat patches of random colour, size and orientation scattered on the cells beside the
    road (off-road tiles and a ring of cells around the map) each episode, gym-duckietown's
    distractors; 0: none. Not in ``default``: each costs render time."""


PRESETS: dict[str, RandomizeConfig] = {
    "default": RandomizeConfig(
        light_intensity=(0.7, 1.3), light_tilt=(0.0, 0.6), ambient=(0.7, 1.3),
        headlight=(0.7, 1.3), floor_color=(0.75, 1.25), horizon_color=(0.7, 1.3),
        object_color=(0.7, 1.3), camera_height=(0.92, 1.08), camera_pitch=(0.8, 1.2),
        camera_fov=(0.8, 1.2), camera_position_noise=0.005, jpeg_quality=(50, 95),
        sensor_noise=(0.0, 4.0), max_speed=(0.9, 1.1), yaw_rate=(0.9, 1.1),
        wheel_distance=(0.9, 1.1), time_constants=(0.8, 1.2), delay=(-1 / 30, 1 / 30),
        trim=0.02),
}
"""Named settings of ``randomize``. ``default`` follows gym-duckietown's domain and dynamics
randomisation; the delay varies by one 30 Hz control step."""

_SCALARS = ("camera_position_noise", "trim")
"""Fields that are one non-negative number, not a range."""
_COUNTS = ("distractors",)
"""Fields that are a whole number >= 0."""
DISTRACTOR_HALF_SIDES = (0.015, 0.06)
"""Range of each half side (m) of a distractor patch."""
_LOWEST = {"jpeg_quality": 1.0, "sensor_noise": 0.0, "light_tilt": 0.0}
"""Least lower bound of a range; multipliers must be positive, the delay is unbounded."""
_HIGHEST = {"jpeg_quality": 100.0, "light_tilt": math.pi / 2}
_ADDITIVE = ("delay",)


def parse_randomize(value: Any, source: str | Path) -> RandomizeConfig | None:
    """The task's ``randomize`` setting checked (None: off)."""
    if value is None or value == "none":
        return None
    if isinstance(value, str):
        return _preset(value, source, "randomize")
    if not isinstance(value, Mapping):
        raise ConfigError(source, "randomize", f"expected none, a preset name "
                          f"({', '.join(PRESETS)}) or a mapping of ranges, got {value!r}")
    values = dict(value)
    base = values.pop("preset", "none")
    config = RandomizeConfig() if base in (None, "none") else \
        _preset(base, source, "randomize.preset")
    names = [f.name for f in dataclasses.fields(RandomizeConfig)]
    changes: dict[str, Any] = {}
    for key, item in values.items():
        where = f"randomize.{key}"
        if key not in names:
            raise ConfigError(source, where, f"unknown setting (known: preset, "
                              f"{', '.join(names)})")
        if key in _COUNTS:
            changes[key] = _count(item, source, where)
        elif key in _SCALARS:
            changes[key] = _scalar(item, source, where)
        else:
            changes[key] = _range(key, item, source, where)
    config = dataclasses.replace(config, **changes)
    return None if config == RandomizeConfig() else config


def _preset(name: Any, source: str | Path, where: str) -> RandomizeConfig:
    if name not in PRESETS:
        raise ConfigError(source, where, f"unknown preset {name!r} (known: none, "
                          f"{', '.join(PRESETS)})")
    return PRESETS[name]


def _number(value: Any, source: str | Path, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(source, where, f"expected a finite number, got {value!r}")
    return float(value)


def _count(value: Any, source: str | Path, where: str) -> int:
    if value is None:
        return 0
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ConfigError(source, where, f"expected a whole number >= 0, got {value!r}")
    return value


def _scalar(value: Any, source: str | Path, where: str) -> float:
    number = 0.0 if value is None else _number(value, source, where)
    if number < 0:
        raise ConfigError(source, where, f"must be >= 0, got {number:g}")
    return number


def _range(key: str, value: Any, source: str | Path, where: str) -> Range | None:
    if value is None:
        return None
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ConfigError(source, where, f"expected [low, high] or null, got {value!r}")
    low, high = (_number(v, source, where) for v in value)
    if low > high:
        raise ConfigError(source, where, f"low {low:g} is above high {high:g}")
    if key in _LOWEST and low < _LOWEST[key]:
        raise ConfigError(source, where, f"must be >= {_LOWEST[key]:g}, got {low:g}")
    if key in _HIGHEST and high > _HIGHEST[key]:
        raise ConfigError(source, where, f"must be <= {_HIGHEST[key]:g}, got {high:g}")
    if key not in _LOWEST and key not in _ADDITIVE and low <= 0:
        raise ConfigError(source, where, f"a multiplier must be > 0, got {low:g}")
    return (low, high)


def max_delay(config: RandomizeConfig | None, motor: MotorConfig) -> float:
    """The longest command delay (s) the episodes can draw."""
    if config is None or config.delay is None:
        return motor.delay
    return max(motor.delay + config.delay[1], 0.0)


def distractor_count(config: RandomizeConfig | None) -> int:
    """The distractor patches the scene must hold for ``config``."""
    return 0 if config is None else config.distractors


def draw_variation(config: RandomizeConfig, motor: MotorConfig, objects: int,
                   random: np.random.RandomState,
                   offroad_cells: Sequence[tuple[float, float]] = (),
                   cell_size: float = 0.0) -> SceneVariation:
    """One episode's variation, drawn from ``random`` in a fixed order, only for the fields
    ``config`` sets (``objects``: the map's object count; distractors lie in the square cells
    of side ``cell_size`` (m) whose south-west corners are ``offroad_cells``)."""

    def factor(bounds: Range | None) -> float:
        return 1.0 if bounds is None else float(random.uniform(*bounds))

    def colour(bounds: Range | None) -> tuple[float, float, float]:
        if bounds is None:
            return (1.0, 1.0, 1.0)
        r, g, b = random.uniform(*bounds, size=3).tolist()
        return (r, g, b)

    nominal = SceneVariation()
    light = nominal.light_direction
    if config.light_tilt is not None:
        tilt = random.uniform(*config.light_tilt)
        azimuth = random.uniform(-math.pi, math.pi)
        light = (math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth),
                 -math.cos(tilt))
    light_intensity, ambient, headlight = (factor(config.light_intensity),
                                           factor(config.ambient), factor(config.headlight))
    floor, horizon = colour(config.floor_color), colour(config.horizon_color)
    objects_rgb = tuple(colour(config.object_color) for _ in range(objects)) \
        if config.object_color is not None else ()
    height, pitch, fov = (factor(config.camera_height), factor(config.camera_pitch),
                          factor(config.camera_fov))
    offset = (0.0, 0.0, 0.0)
    if config.camera_position_noise > 0:
        noise = config.camera_position_noise
        x, y, z = random.uniform(-noise, noise, size=3).tolist()
        offset = (x, y, z)
    quality = 0 if config.jpeg_quality is None else int(random.randint(
        round(config.jpeg_quality[0]), round(config.jpeg_quality[1]) + 1))
    noise_std = 0.0 if config.sensor_noise is None else float(random.uniform(*config.sensor_noise))
    noise_seed = int(random.randint(2**31)) if noise_std > 0 else 0
    speed, yaw, distance, lag = (factor(config.max_speed), factor(config.yaw_rate),
                                 factor(config.wheel_distance), factor(config.time_constants))
    delay = motor.delay if config.delay is None else \
        max(motor.delay + float(random.uniform(*config.delay)), 0.0)
    trim = float(random.normal(0.0, config.trim)) if config.trim > 0 else 0.0
    distractors = tuple(_draw_distractor(random, offroad_cells, cell_size)
                        for _ in range(config.distractors if offroad_cells else 0))
    return SceneVariation(
        light_direction=light, light_intensity=light_intensity, ambient=ambient,
        headlight=headlight, floor_color=floor, horizon_color=horizon,
        object_colors=objects_rgb, camera_height=C.CAMERA_HEIGHT * height,
        camera_pitch=C.CAMERA_PITCH * pitch, camera_fovy=C.CAMERA_FOVY * fov,
        camera_offset=offset, jpeg_quality=quality, noise_std=noise_std, noise_seed=noise_seed,
        motor=MotorConfig(max_speed=motor.max_speed * speed,
                          yaw_rate_per_duty=motor.yaw_rate_per_duty * yaw / distance,
                          linear_time_constant=motor.linear_time_constant * lag,
                          yaw_time_constant=motor.yaw_time_constant * lag, delay=delay),
        trim=trim, distractors=distractors)


def _draw_distractor(random: np.random.RandomState, cells: Sequence[tuple[float, float]],
                     cell_size: float) -> tuple[float, float, float, float, float, float, float,
                                                float]:
    """One patch: (x, y, yaw, half length, half width, r, g, b) in a random cell."""
    x0, y0 = cells[random.randint(len(cells))]
    x, y = x0 + random.uniform(0.0, cell_size), y0 + random.uniform(0.0, cell_size)
    yaw = random.uniform(-math.pi, math.pi)
    half_length, half_width = random.uniform(*DISTRACTOR_HALF_SIDES, size=2).tolist()
    r, g, b = random.uniform(0.0, 1.0, size=3).tolist()
    return (float(x), float(y), float(yaw), half_length, half_width, r, g, b)


__all__ = ["PRESETS", "RandomizeConfig", "distractor_count", "draw_variation", "max_delay",
           "parse_randomize"]
