"""Per-episode variations of the scene: appearance, camera pose and motor parameters written
into a compiled model.

A :class:`SceneVariation` holds plain values (what to write, not how it was drawn); the task
draws it (:mod:`crllk.tasks.randomization`). :class:`VariationTargets` finds the model fields
a variation changes and remembers their compiled values, so that :func:`apply_appearance` and
:func:`apply_dynamics` scale from those and restore them when given None. Only
visual and actuator fields change: no texture is re-uploaded and the renderers stay valid.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, fields
from typing import Any

import mujoco
import numpy as np

from crllk.sim import constants as C
from crllk.sim.motor import MotorConfig

SUN = "sun"
"""Name of the scene's directional light."""
FLOOR_MATERIAL = "map"
"""Material of the textured floor (tiles and markings)."""
SURROUNDINGS = "surroundings"
"""The ground plane beyond the map's edge: the horizon's colour."""
FLOOR_LIGHTING = 1.0
"""Approximate light falling on the floor in the nominal scene (headlight ambient plus the
diffuse terms): a floor brighter than its texture is emission ``(brightness - 1) *`` this."""


@dataclass(frozen=True)
class SceneVariation:
    """What one episode changes, as plain values. Multipliers are relative to the compiled
    scene; the camera and motor values are absolute."""

    light_direction: tuple[float, float, float] = (0.3, 0.2, -1.0)
    """Direction the sun shines in (world frame, any length)."""
    light_intensity: float = 1.0
    """Multiplier of the sun's diffuse colour."""
    ambient: float = 1.0
    """Multiplier of the headlight's ambient colour."""
    headlight: float = 1.0
    """Multiplier of the headlight's diffuse colour."""
    floor_color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """RGB multipliers of the floor (tiles and markings)."""
    horizon_color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """RGB multipliers of the ground beyond the map."""
    object_colors: tuple[tuple[float, float, float], ...] = ()
    """RGB multipliers of each map object's parts, in the map's order (empty: unchanged);
    colours saturate at 1."""
    camera_height: float = C.CAMERA_HEIGHT
    """Camera height above the floor (m)."""
    camera_pitch: float = C.CAMERA_PITCH
    """Camera pitch below the horizontal (rad)."""
    camera_fovy: float = C.CAMERA_FOVY
    """Camera vertical field of view (degrees)."""
    camera_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Camera position noise in the robot's frame (x forward, y left, z up) (m)."""
    jpeg_quality: int = 0
    """Quality (1-100) of the JPEG-like compression of camera images; 0: none."""
    noise_std: float = 0.0
    """Standard deviation of the camera's Gaussian sensor noise (levels of 255)."""
    noise_seed: int = 0
    """Key of the per-frame sensor noise (:func:`crllk.sim.camera_effects.add_noise`)."""
    motor: MotorConfig = field(default_factory=MotorConfig)
    """The motor model of the episode."""
    trim: float = 0.0
    """Left/right asymmetry: the right duty is scaled by (1 + trim), the left by (1 - trim)."""

    def as_dict(self) -> dict[str, Any]:
        """Plain Python values (tuples as lists, the motor as a mapping)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "motor":
                value = {m.name: getattr(value, m.name) for m in fields(MotorConfig)}
            elif isinstance(value, tuple):
                value = [list(v) if isinstance(v, tuple) else v for v in value]
            out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> SceneVariation:
        """The inverse of :meth:`as_dict`."""
        values = dict(values)
        values["motor"] = MotorConfig(**values["motor"])
        for name in ("light_direction", "floor_color", "horizon_color", "camera_offset"):
            values[name] = tuple(values[name])
        values["object_colors"] = tuple(tuple(c) for c in values["object_colors"])
        return cls(**values)


class VariationTargets:
    """The model fields a variation writes, and their compiled values."""

    def __init__(self, model: mujoco.MjModel):
        def ident(kind: mujoco.mjtObj, name: str) -> int:
            return mujoco.mj_name2id(model, kind, name)

        self.sun = ident(mujoco.mjtObj.mjOBJ_LIGHT, SUN)
        self.floor = ident(mujoco.mjtObj.mjOBJ_MATERIAL, FLOOR_MATERIAL)
        self.surroundings = ident(mujoco.mjtObj.mjOBJ_GEOM, SURROUNDINGS)
        self.camera = ident(mujoco.mjtObj.mjOBJ_CAMERA, C.CAMERA)
        self.actuators = [ident(mujoco.mjtObj.mjOBJ_ACTUATOR, name)
                          for name in (C.FORWARD_ACTUATOR, C.TURN_ACTUATOR)]
        self.object_geoms = _object_geoms(model)
        """Visual geom ids of each map object, in the map's order."""
        self.sun_diffuse = model.light_diffuse[self.sun].copy()
        self.light_dir = model.light_dir[self.sun].copy()
        self.head_ambient = model.vis.headlight.ambient.copy()
        self.head_diffuse = model.vis.headlight.diffuse.copy()
        self.floor_rgba = model.mat_rgba[self.floor].copy()
        self.floor_emission = float(model.mat_emission[self.floor])
        self.surroundings_rgba = model.geom_rgba[self.surroundings].copy()
        self.object_rgba = [model.geom_rgba[ids].copy() for ids in self.object_geoms]
        self.cam_pos = model.cam_pos[self.camera].copy()
        self.cam_quat = model.cam_quat[self.camera].copy()
        self.cam_fovy = float(model.cam_fovy[self.camera])
        self.dynprm = model.actuator_dynprm[self.actuators, 0].copy()
        self.delay = model.actuator_delay[self.actuators].copy()


def _object_geoms(model: mujoco.MjModel) -> list[np.ndarray]:
    """Visual geom ids per map object (bodies ``obstacle/<k>_<kind>``), by ``k``."""
    by_index: dict[int, list[int]] = {}
    for geom in range(model.ngeom):
        body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[geom]) or ""
        if body.startswith(C.OBSTACLE_PREFIX) and model.geom_group[geom] == 1:
            index = int(body[len(C.OBSTACLE_PREFIX):].split("_", 1)[0])
            by_index.setdefault(index, []).append(geom)
    return [np.array(by_index.get(k, []), dtype=int) for k in range(max(by_index, default=-1) + 1)]


@functools.lru_cache(maxsize=256)
def camera_pose(variation: SceneVariation) -> tuple[np.ndarray, np.ndarray]:
    """The robot camera's position and orientation quaternion in the chassis frame (whose
    origin is one wheel radius above the floor). MuJoCo cameras look along their -z axis."""
    pitch = variation.camera_pitch
    ahead, left, up = variation.camera_offset
    position = np.array([C.CAMERA_AHEAD + ahead, left,
                         variation.camera_height - C.WHEEL_RADIUS + up])
    x_axis = np.array([0.0, -1.0, 0.0])
    y_axis = np.array([math.sin(pitch), 0.0, math.cos(pitch)])
    z_axis = np.cross(x_axis, y_axis)
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x_axis, y_axis, z_axis]).flatten())
    return position, quat


def apply_appearance(model: mujoco.MjModel, targets: VariationTargets,
                     variation: SceneVariation | None) -> None:
    """Write the lights, colours and camera of ``variation`` into ``model`` (None: the
    compiled values). Lights and cameras take effect once ``mj_camlight`` has run."""
    t = targets
    if variation is None:
        model.light_diffuse[t.sun] = t.sun_diffuse
        model.light_dir[t.sun] = t.light_dir
        model.vis.headlight.ambient = t.head_ambient
        model.vis.headlight.diffuse = t.head_diffuse
        model.mat_rgba[t.floor] = t.floor_rgba
        model.mat_emission[t.floor] = t.floor_emission
        model.geom_rgba[t.surroundings] = t.surroundings_rgba
        for ids, rgba in zip(t.object_geoms, t.object_rgba, strict=True):
            model.geom_rgba[ids] = rgba
        model.cam_pos[t.camera] = t.cam_pos
        model.cam_quat[t.camera] = t.cam_quat
        model.cam_fovy[t.camera] = t.cam_fovy
        return
    v = variation
    direction = np.asarray(v.light_direction, dtype=float)
    model.light_dir[t.sun] = direction / np.linalg.norm(direction)
    model.light_diffuse[t.sun] = t.sun_diffuse * v.light_intensity
    model.vis.headlight.ambient = t.head_ambient * v.ambient
    model.vis.headlight.diffuse = t.head_diffuse * v.headlight
    floor = np.asarray(v.floor_color)
    scale = max(float(floor.max()), 1.0)  # colours saturate at 1: brighter is emission
    model.mat_rgba[t.floor, :3] = t.floor_rgba[:3] * floor / scale
    model.mat_emission[t.floor] = t.floor_emission + (scale - 1.0) * FLOOR_LIGHTING
    model.geom_rgba[t.surroundings, :3] = np.minimum(
        t.surroundings_rgba[:3] * np.asarray(v.horizon_color), 1.0)
    for ids, rgba, color in zip(t.object_geoms, t.object_rgba, v.object_colors, strict=False):
        model.geom_rgba[ids, :3] = np.minimum(rgba[:, :3] * np.asarray(color), 1.0)
    position, quat = camera_pose(v)
    model.cam_pos[t.camera] = position
    model.cam_quat[t.camera] = quat
    model.cam_fovy[t.camera] = v.camera_fovy


def apply_dynamics(model: mujoco.MjModel, targets: VariationTargets,
                   variation: SceneVariation | None) -> None:
    """Write the motor filter time constants and command delay of ``variation`` into
    ``model`` (None: the compiled values). Gains and trim act in the commands
    (:meth:`crllk.sim.physics.Physics.set_wheel_duty`)."""
    t = targets
    if variation is None:
        model.actuator_dynprm[t.actuators, 0] = t.dynprm
        model.actuator_delay[t.actuators] = t.delay
        return
    motor = variation.motor
    model.actuator_dynprm[t.actuators, 0] = (motor.linear_time_constant,
                                              motor.yaw_time_constant)
    model.actuator_delay[t.actuators] = motor.delay
