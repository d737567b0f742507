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
DISTRACTOR_HALF_THICKNESS = 0.0005
"""Half the thickness (m) of a distractor patch lying on the floor."""
HIDDEN_DEPTH = -1.0
"""Height (m) of a distractor patch no variation shows: below the floor, out of sight."""
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
    distractors: tuple[tuple[float, float, float, float, float, float, float, float], ...] = ()
    """Flat patches on the floor, each (x, y, yaw, half length, half width, r, g, b) (m, rad,
    colour in [0, 1]); the scene's other patches stay hidden."""

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
        values["distractors"] = tuple(tuple(d) for d in values.get("distractors", ()))
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
        self.distractor_geoms = np.array(
            [g for g in range(model.ngeom)
             if (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or "").startswith(
                 C.DISTRACTOR_PREFIX)], dtype=int)
        """Geom ids of the scene's distractor patches (none unless compiled with them)."""
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
        self.distractor_pos = model.geom_pos[self.distractor_geoms].copy()
        self.distractor_quat = model.geom_quat[self.distractor_geoms].copy()
        self.distractor_size = model.geom_size[self.distractor_geoms].copy()
        self.distractor_rgba = model.geom_rgba[self.distractor_geoms].copy()
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


@dataclass(frozen=True)
class Appearance:
    """The values :func:`apply_appearance` writes for one variation, computed once: writing
    them is a few array copies (the shared model of a batched env takes each simulation's in
    turn before every render)."""

    light_dir: np.ndarray
    light_diffuse: np.ndarray
    head_ambient: np.ndarray
    head_diffuse: np.ndarray
    floor_rgb: np.ndarray
    floor_emission: float
    geoms: np.ndarray
    """Ids of the geoms whose colour is written: the surroundings, then the objects'."""
    geom_rgb: np.ndarray
    """Their RGB (float32, one row per geom)."""
    cam_pos: np.ndarray
    cam_quat: np.ndarray
    cam_fovy: float
    distractor_pos: np.ndarray
    """Position, orientation, size and colour of each of the scene's distractor patches."""
    distractor_quat: np.ndarray
    distractor_size: np.ndarray
    distractor_rgba: np.ndarray
    distractor_xmat: np.ndarray
    """Their orientation matrices (row-major, one row of 9 per patch)."""


def apply_appearance(model: mujoco.MjModel, targets: VariationTargets,
                     variation: SceneVariation | None) -> None:
    """Write the lights, colours and camera of ``variation`` into ``model`` (None: the
    compiled values). Lights and cameras take effect once ``mj_camlight`` has run."""
    write_appearance(model, targets, appearance(targets, variation))


def write_appearance(model: mujoco.MjModel, targets: VariationTargets,
                     values: Appearance) -> None:
    """Write :func:`appearance` values into ``model``."""
    model.light_dir[targets.sun] = values.light_dir
    model.light_diffuse[targets.sun] = values.light_diffuse
    model.vis.headlight.ambient = values.head_ambient
    model.vis.headlight.diffuse = values.head_diffuse
    model.mat_rgba[targets.floor, :3] = values.floor_rgb
    model.mat_emission[targets.floor] = values.floor_emission
    model.geom_rgba[values.geoms, :3] = values.geom_rgb
    model.cam_pos[targets.camera] = values.cam_pos
    model.cam_quat[targets.camera] = values.cam_quat
    model.cam_fovy[targets.camera] = values.cam_fovy
    if targets.distractor_geoms.size:
        ids = targets.distractor_geoms
        model.geom_pos[ids] = values.distractor_pos
        model.geom_quat[ids] = values.distractor_quat
        model.geom_size[ids] = values.distractor_size
        model.geom_rgba[ids] = values.distractor_rgba


@functools.lru_cache(maxsize=256)
def appearance(targets: VariationTargets, variation: SceneVariation | None) -> Appearance:
    """What :func:`apply_appearance` writes for ``variation`` (None: the compiled values)."""
    t = targets
    if variation is None:
        return Appearance(
            t.light_dir, t.sun_diffuse, t.head_ambient, t.head_diffuse, t.floor_rgba[:3],
            t.floor_emission, *_geom_colours(t, t.surroundings_rgba[:3],
                                             [rgba[:, :3] for rgba in t.object_rgba]),
            t.cam_pos, t.cam_quat, t.cam_fovy, *_distractors(t, ()))
    v = variation
    direction = np.asarray(v.light_direction, dtype=float)
    floor = np.asarray(v.floor_color)
    scale = max(float(floor.max()), 1.0)  # colours saturate at 1: brighter is emission
    horizon = np.minimum(t.surroundings_rgba[:3] * np.asarray(v.horizon_color), 1.0)
    objects = [np.minimum(rgba[:, :3] * np.asarray(color), 1.0)
               for rgba, color in zip(t.object_rgba, v.object_colors, strict=False)]
    position, quat = camera_pose(v)
    return Appearance(
        direction / np.linalg.norm(direction), t.sun_diffuse * v.light_intensity,
        t.head_ambient * v.ambient, t.head_diffuse * v.headlight,
        (t.floor_rgba[:3] * floor / scale).astype(np.float32),
        t.floor_emission + (scale - 1.0) * FLOOR_LIGHTING,
        *_geom_colours(t, horizon, objects), position, quat, v.camera_fovy,
        *_distractors(t, v.distractors))


def _distractors(targets: VariationTargets, patches: tuple[tuple[float, ...], ...]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Position, quaternion, size, RGBA and orientation-matrix rows of the scene's distractor
    geoms: the first
    ``len(patches)`` lying on the floor as drawn, the others hidden as compiled."""
    t = targets
    pos, quat = t.distractor_pos.copy(), t.distractor_quat.copy()
    size, rgba = t.distractor_size.copy(), t.distractor_rgba.copy()
    for k, (x, y, yaw, half_length, half_width, r, g, b) in enumerate(
            patches[:len(t.distractor_geoms)]):
        pos[k] = (x, y, DISTRACTOR_HALF_THICKNESS)
        quat[k] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        size[k] = (half_length, half_width, DISTRACTOR_HALF_THICKNESS)
        rgba[k] = (r, g, b, 1.0)
    xmat = np.empty((len(quat), 9))
    for k, q in enumerate(quat):
        mujoco.mju_quat2Mat(xmat[k], q)
    return pos, quat, size, rgba.astype(np.float32), xmat


def place_distractors(data: mujoco.MjData, targets: VariationTargets,
                      values: Appearance) -> None:
    """Write the distractor patches' world poses into ``data``: fixed geoms of the world body
    whose pose the model holds, which ``mj_kinematics`` would copy from a model that copies
    sharing it may have rewritten since."""
    data.geom_xpos[targets.distractor_geoms] = values.distractor_pos
    data.geom_xmat[targets.distractor_geoms] = values.distractor_xmat


def _geom_colours(targets: VariationTargets, surroundings: np.ndarray,
                  objects: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Geom ids and float32 RGB rows: the surroundings', then the first ``len(objects)``
    objects' (the others keep what the model holds)."""
    ids = [np.array([targets.surroundings]), *targets.object_geoms[:len(objects)]]
    return np.concatenate(ids), np.concatenate([surroundings[None], *objects]).astype(np.float32)


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
