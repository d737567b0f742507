"""Build a MuJoCo scene from a Duckietown map: textured floor, obstacles, lights, cameras, robot.

The scene is an ``mujoco.MjSpec``: the map's floor is one textured quad (markings drawn by
:mod:`crllk.sim.texture`), physics uses one invisible ground plane, each object is a few visual
primitives plus, if the robot collides with it, an invisible collision box of its footprint,
and the Duckiebot from ``assets/mjcf/duckiebot.xml`` is attached under the prefix
``duckiebot/``.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

from crllk.maps import DuckietownMap, MapObject
from crllk.paths import DUCKIEBOT_XML
from crllk.sim import constants as C
from crllk.sim.motor import MotorConfig
from crllk.sim.texture import texture_png
from crllk.sim.variation import (
    DISTRACTOR_HALF_THICKNESS,
    FLOOR_MATERIAL,
    HIDDEN_DEPTH,
    SUN,
    SURROUNDINGS,
)

_SCENE_MARGIN = 1.0
"""Ground visible beyond the map's edge (m)."""
_OVERHEAD_HEIGHT = 6.0
"""Height of the overhead camera above the floor (m)."""
_OBSTACLE_CONTYPE, _OBSTACLE_CONAFFINITY = 0, 2
"""Obstacles touch only the chassis footprint (contype 2)."""


def build_spec(dmap: DuckietownMap, motor: MotorConfig | None = None,
               max_delay: float = 0.0, distractors: int = 0) -> mujoco.MjSpec:
    """The whole scene (map and robot) as an ``MjSpec`` ready to compile; the actuators keep
    enough history for command delays up to ``max_delay`` (s) or the motor's own, and the
    scene holds ``distractors`` hidden patches that scene variations place and colour."""
    spec = mujoco.MjSpec()
    spec.modelname = f"duckietown_{dmap.name}"
    spec.option.timestep = C.PHYSICS_TIMESTEP
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    _set_visual(spec, dmap)
    _add_floor(spec, dmap)
    _add_lights(spec, dmap)
    _add_overhead_camera(spec, dmap)
    for index, obj in enumerate(dmap.objects):
        _add_obstacle(spec, obj, index)
    for index in range(distractors):
        _add_distractor(spec, index)
    robot = mujoco.MjSpec.from_file(str(DUCKIEBOT_XML))
    _configure_motors(robot, motor or MotorConfig(), max_delay)
    spec.attach(robot, prefix=C.ROBOT_PREFIX, frame=spec.worldbody.add_frame())
    return spec


def compile_scene(dmap: DuckietownMap, motor: MotorConfig | None = None,
                  max_delay: float = 0.0, distractors: int = 0) -> mujoco.MjModel:
    """Compile the scene of ``dmap`` into an ``MjModel`` (see :func:`build_spec`)."""
    return build_spec(dmap, motor, max_delay, distractors).compile()


def export_scene(dmap: DuckietownMap, directory: str | Path) -> Path:
    """Write a standalone MJCF of the scene (``<map>.xml`` and its texture) that MuJoCo's own
    viewer opens: ``python -m mujoco.viewer --mjcf=<path>``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    spec = build_spec(dmap)
    spec.compile()
    (directory / _texture_file(dmap)).write_bytes(texture_png(dmap))
    path = directory / f"{dmap.name}.xml"
    path.write_text(spec.to_xml())
    return path


def _texture_file(dmap: DuckietownMap) -> str:
    return f"{dmap.name}_texture.png"


def _set_visual(spec: mujoco.MjSpec, dmap: DuckietownMap) -> None:
    # Software rendering: no shadow map and no multisampling (about 50x faster).
    spec.visual.quality.shadowsize = 0
    spec.visual.quality.offsamples = 0
    spec.visual.headlight.ambient = [0.45, 0.45, 0.45]
    spec.visual.headlight.diffuse = [0.35, 0.35, 0.35]
    spec.visual.headlight.specular = [0.0, 0.0, 0.0]
    spec.visual.map.znear = 0.002
    spec.visual.map.zfar = 20.0
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 960
    spec.stat.extent = max(dmap.width, dmap.height)
    spec.stat.center = [dmap.width / 2, dmap.height / 2, 0.0]


def _add_floor(spec: mujoco.MjSpec, dmap: DuckietownMap) -> None:
    texture_file = _texture_file(dmap)
    spec.assets = {texture_file: texture_png(dmap)}
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, rgb1=[0.62, 0.72, 0.82],
                     rgb2=[0.85, 0.85, 0.85], width=64, height=64)
    spec.add_texture(name="map", type=mujoco.mjtTexture.mjTEXTURE_2D, file=texture_file)
    material = spec.add_material(name=FLOOR_MATERIAL, rgba=[1, 1, 1, 1], specular=0.0,
                                 shininess=0.0)
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "map"
    material.texrepeat = [1, 1]
    material.texuniform = False
    half_w, half_h = dmap.width / 2, dmap.height / 2
    spec.worldbody.add_geom(
        name="map", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[half_w, half_h, 0.1],
        pos=[half_w, half_h, 0.0], material="map", contype=0, conaffinity=0, group=0)
    spec.worldbody.add_geom(
        name=SURROUNDINGS, type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[half_w + _SCENE_MARGIN, half_h + _SCENE_MARGIN, 0.1],
        pos=[half_w, half_h, -0.002], rgba=[0.22, 0.22, 0.24, 1], contype=0, conaffinity=0)
    # Physics: one flat invisible ground; road limits are checked geometrically, not by contact.
    spec.worldbody.add_geom(
        name="ground", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.1], contype=1,
        conaffinity=1, group=3, rgba=[0, 0, 0, 0], friction=[1.0, 0.005, 0.0001])


def _add_lights(spec: mujoco.MjSpec, dmap: DuckietownMap) -> None:
    spec.worldbody.add_light(
        name=SUN, type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, castshadow=False,
        pos=[dmap.width / 2, dmap.height / 2, 4.0], dir=[0.3, 0.2, -1.0],
        diffuse=[0.55, 0.55, 0.55], specular=[0.05, 0.05, 0.05])


def _add_overhead_camera(spec: mujoco.MjSpec, dmap: DuckietownMap) -> None:
    camera = spec.worldbody.add_camera(
        name=C.OVERHEAD_CAMERA, pos=[dmap.width / 2, dmap.height / 2, _OVERHEAD_HEIGHT])
    camera.proj = mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC
    camera.fovy = max(dmap.height, dmap.width * 3 / 4)  # orthographic: vertical extent (m)


# Visual parts per object kind, in the object's frame scaled to its footprint box
# (length, width, height) = (1, 1, 1): (geom type, size, position, rgba).
_BOX, _SPHERE, _CYL, _ELL = (mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_SPHERE,
                             mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_ELLIPSOID)
_YELLOW, _ORANGE, _WHITE, _DARK = ([0.98, 0.85, 0.15, 1], [0.95, 0.42, 0.05, 1],
                                   [0.95, 0.95, 0.95, 1], [0.1, 0.1, 0.12, 1])
_PARTS: dict[str, list[tuple]] = {
    "duckie": [(_ELL, (0.5, 0.5, 0.33), (0, 0, 0.33), _YELLOW),
               (_SPHERE, (0.28,), (0.18, 0, 0.72), _YELLOW),
               (_ELL, (0.16, 0.12, 0.05), (0.45, 0, 0.7), _ORANGE)],
    "cone": [(_BOX, (0.5, 0.5, 0.04), (0, 0, 0.04), _ORANGE),
             (_CYL, (0.38, 0.25), (0, 0, 0.3), _ORANGE),
             (_CYL, (0.3, 0.12), (0, 0, 0.62), _WHITE),
             (_CYL, (0.2, 0.15), (0, 0, 0.85), _ORANGE)],
    "barrier": [(_BOX, (0.5, 0.5, 0.25), (0, 0, 0.75), [0.9, 0.1, 0.1, 1]),
                (_BOX, (0.45, 0.3, 0.25), (0, 0, 0.25), _WHITE)],
    "duckiebot": [(_BOX, (0.5, 0.45, 0.35), (0, 0, 0.4), _DARK),
                  (_SPHERE, (0.18,), (-0.1, 0, 0.85), _YELLOW)],
    "bus": [(_BOX, (0.5, 0.5, 0.5), (0, 0, 0.5), [0.95, 0.75, 0.1, 1]),
            (_BOX, (0.45, 0.51, 0.12), (0, 0, 0.7), [0.2, 0.25, 0.3, 1])],
    "truck": [(_BOX, (0.3, 0.5, 0.5), (0.2, 0, 0.5), [0.2, 0.4, 0.8, 1]),
              (_BOX, (0.2, 0.5, 0.35), (-0.3, 0, 0.35), [0.8, 0.8, 0.85, 1])],
    "tree": [(_CYL, (0.12, 0.2), (0, 0, 0.2), [0.45, 0.3, 0.15, 1]),
             (_ELL, (0.5, 0.5, 0.4), (0, 0, 0.6), [0.2, 0.55, 0.2, 1])],
    "sign_blank": [(_CYL, (0.1, 0.4), (0, 0, 0.4), [0.6, 0.6, 0.6, 1]),
                   (_BOX, (0.1, 0.5, 0.2), (0, 0, 0.8), _WHITE)],
    "house": [(_BOX, (0.5, 0.5, 0.33), (0, 0, 0.33), [0.85, 0.8, 0.7, 1]),
              (_BOX, (0.5, 0.5, 0.17), (0, 0, 0.83), [0.6, 0.2, 0.15, 1])],
    "building": [(_BOX, (0.5, 0.5, 0.5), (0, 0, 0.5), [0.7, 0.7, 0.72, 1]),
                 (_BOX, (0.51, 0.4, 0.05), (0, 0, 0.75), [0.3, 0.4, 0.5, 1])],
    "trafficlight": [(_CYL, (0.15, 0.5), (0, 0, 0.5), [0.3, 0.3, 0.3, 1]),
                     (_BOX, (0.15, 0.5, 0.03), (0, 0, 0.9), [0.3, 0.3, 0.3, 1]),
                     (_BOX, (0.3, 0.08, 0.06), (0, 0, 0.85), [0.9, 0.15, 0.1, 1])],
    "checkerboard": [(_BOX, (0.05, 0.5, 0.5), (0, 0, 0.5), _WHITE)],
}
_SIGN_POLE = (_CYL, (0.12, 0.35), (0, 0, 0.35), [0.6, 0.6, 0.6, 1])
_SIGN_FACE_RGBA = {"sign_stop": [0.85, 0.1, 0.1, 1], "sign_yield": [0.85, 0.1, 0.1, 1],
                   "sign_do_not_enter": [0.85, 0.1, 0.1, 1]}
"""Colour of a sign's face (white where not given)."""


def _parts(kind: str) -> list[tuple]:
    """Visual parts of an object kind; every traffic sign is a pole carrying a plate."""
    if kind in _PARTS:
        return _PARTS[kind]
    face = _SIGN_FACE_RGBA.get(kind, _WHITE)
    return [_SIGN_POLE, (_BOX, (0.15, 0.5, 0.15), (0, 0, 0.85), face)]


def _add_obstacle(spec: mujoco.MjSpec, obj: MapObject, index: int) -> None:
    body = spec.worldbody.add_body(
        name=f"{C.OBSTACLE_PREFIX}{index}_{obj.kind}", pos=[obj.x, obj.y, 0.0],
        quat=[math.cos(obj.yaw / 2), 0, 0, math.sin(obj.yaw / 2)])
    dims = np.array([obj.length, obj.width, obj.height])
    if obj.collidable:
        body.add_geom(name=f"{C.OBSTACLE_PREFIX}{index}", type=_BOX,
                      size=[obj.length / 2, obj.width / 2, obj.height / 2],
                      pos=[0, 0, obj.height / 2], contype=_OBSTACLE_CONTYPE,
                      conaffinity=_OBSTACLE_CONAFFINITY, group=3, rgba=[1, 0, 0, 0.2])
    add_object_parts(body, obj.kind, dims)


def add_object_parts(body: mujoco.MjsBody, kind: str, dims: np.ndarray) -> None:
    """The visual primitives of an object of ``kind`` whose footprint box is ``dims``
    (length, width, height) (m), in ``body``'s frame (the box standing on its origin)."""
    for geom_type, size, pos, rgba in _parts(kind):
        scaled_size = _scale_size(geom_type, np.array(size), dims)
        body.add_geom(type=geom_type, size=scaled_size, pos=(np.array(pos) * dims).tolist(),
                      rgba=rgba, contype=0, conaffinity=0, group=1)


def _add_distractor(spec: mujoco.MjSpec, index: int) -> None:
    """A flat box that touches nothing, hidden below the floor until a variation moves it."""
    spec.worldbody.add_geom(name=f"{C.DISTRACTOR_PREFIX}{index}", type=_BOX,
                            size=[0.05, 0.05, DISTRACTOR_HALF_THICKNESS],
                            pos=[0.0, 0.0, HIDDEN_DEPTH], rgba=[0, 0, 0, 0], contype=0,
                            conaffinity=0, group=1)


def _scale_size(geom_type, size: np.ndarray, dims: np.ndarray) -> list[float]:
    if geom_type == _SPHERE:
        return [float(size[0] * min(dims))]
    if geom_type == _CYL:
        return [float(size[0] * min(dims[:2])), float(size[1] * dims[2])]
    return (size * dims).tolist()


def _configure_motors(robot: mujoco.MjSpec, motor: MotorConfig, max_delay: float) -> None:
    """Set the actuators' delay, history length (for delays up to ``max_delay`` s or the
    motor's) and filter time constants from ``motor``."""
    samples = math.ceil(max(motor.delay, max_delay) / C.PHYSICS_TIMESTEP) + 2
    for name, time_constant in (("forward", motor.linear_time_constant),
                                ("turn", motor.yaw_time_constant)):
        actuator = robot.actuator(name)
        actuator.delay = motor.delay
        actuator.nsample = samples
        actuator.dynprm[0] = time_constant
