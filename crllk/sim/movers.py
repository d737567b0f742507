"""Moving agents in the scene: other Duckiebots and duckie pedestrians as mocap bodies.

Movers are kinematic: the task sets each one's pose every control step
(:meth:`Movers.set_poses`) and MuJoCo carries it through the physics steps without
integrating it, so traffic costs no degrees of freedom and cannot destabilise the physics. A
vehicle is the Duckiebot of ``assets/mjcf/duckiebot.xml`` without its joints, actuators,
cameras and wheel contacts; a pedestrian is the map's duckie. Each carries an invisible
collision box of its footprint that, like the static obstacles, touches only the robot's
chassis, so a contact is a collision of the robot with it. Their poses live in the MuJoCo data
(``mocap_pos``, ``mocap_quat``), which every full-state snapshot holds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from crllk.maps.objects import OBJECT_SIZES
from crllk.paths import DUCKIEBOT_XML
from crllk.sim import constants as C
from crllk.sim.scene import add_object_parts

PEDESTRIAN_HEIGHT = 0.08
"""Height of a duckie pedestrian (m)."""
PEDESTRIAN_SIZE = tuple(v * PEDESTRIAN_HEIGHT / OBJECT_SIZES["duckie"][2]
                        for v in OBJECT_SIZES["duckie"])
"""A pedestrian's footprint length x width x height (m), the map's duckie scaled."""
SLICES, STACKS = 12, 6
"""How finely a scene with movers draws curved surfaces (MuJoCo's ``visual.quality``; its
defaults are 28 and 16): the movers' spheres, ellipsoids and cylinders are most of what such a
scene draws, and at the robot camera's 60×80 render the coarser ones cost far fewer triangles
and differ from the fine ones only along their outlines (scenes without movers keep the
defaults, so their images are unchanged; ``python -m crllk.bench --traffic`` times the
result)."""
_CHASSIS = "chassis"
_MOVER_CONTYPE, _MOVER_CONAFFINITY = 0, 2
"""Movers touch only the robot's chassis footprint (contype 2), as obstacles do."""


def vehicle_name(index: int) -> str:
    """Prefix of vehicle ``index``'s elements."""
    return f"{C.VEHICLE_PREFIX}{index}/"


def pedestrian_name(index: int) -> str:
    """Name of pedestrian ``index``'s body (and prefix of its footprint)."""
    return f"{C.PEDESTRIAN_PREFIX}{index}"


def add_movers(spec: mujoco.MjSpec, vehicles: int, pedestrians: int) -> None:
    """Add ``vehicles`` Duckiebots and ``pedestrians`` duckies as mocap bodies to ``spec``,
    whose curved surfaces are then drawn with :data:`SLICES` and :data:`STACKS`."""
    if vehicles or pedestrians:
        spec.visual.quality.numslices, spec.visual.quality.numstacks = SLICES, STACKS
    for index in range(vehicles):
        spec.attach(_vehicle_spec(), prefix=vehicle_name(index),
                    frame=spec.worldbody.add_frame())
    length, width, height = PEDESTRIAN_SIZE
    for index in range(pedestrians):
        body = spec.worldbody.add_body(name=pedestrian_name(index), mocap=True)
        body.add_geom(name=f"{pedestrian_name(index)}/{C.MOVER_FOOTPRINT}",
                      type=mujoco.mjtGeom.mjGEOM_BOX, size=[length / 2, width / 2, height / 2],
                      pos=[0, 0, height / 2], contype=_MOVER_CONTYPE,
                      conaffinity=_MOVER_CONAFFINITY, group=3, rgba=[1, 0, 0, 0.2])
        add_object_parts(body, "duckie", np.array(PEDESTRIAN_SIZE))


def _vehicle_spec() -> mujoco.MjSpec:
    """The Duckiebot as a rigid mocap body: joints, tendons, actuators, cameras and sites
    removed, wheels and caster not colliding, the footprint touching only the robot."""
    robot = mujoco.MjSpec.from_file(str(DUCKIEBOT_XML))
    for element in [*robot.actuators, *robot.tendons, *robot.joints, *robot.cameras,
                    *robot.sites]:
        robot.delete(element)
    robot.body(_CHASSIS).mocap = True
    for geom in robot.geoms:
        if geom.name == C.MOVER_FOOTPRINT:
            geom.contype, geom.conaffinity = _MOVER_CONTYPE, _MOVER_CONAFFINITY
        elif geom.contype or geom.conaffinity:
            robot.delete(geom)
    return robot


class Movers:
    """The movers of a compiled scene: their mocap slots and collision geoms."""

    def __init__(self, model: mujoco.MjModel) -> None:
        bodies = [model.body(f"{vehicle_name(k)}{_CHASSIS}").id
                  for k in range(_count(model, C.VEHICLE_PREFIX))]
        self.vehicles = len(bodies)
        bodies += [model.body(pedestrian_name(k)).id
                   for k in range(_count(model, C.PEDESTRIAN_PREFIX))]
        self.mocap = np.array([model.body_mocapid[b] for b in bodies], dtype=int)
        """Mocap index of each mover: the vehicles, then the pedestrians."""
        self.heights = np.array([C.WHEEL_RADIUS] * self.vehicles
                                + [0.0] * (len(bodies) - self.vehicles))
        """Height (m) of each mover's body frame above the floor."""
        self._heights: list[float] = self.heights.tolist()
        self.of_geom = np.full(model.ngeom, -1, dtype=int)
        """The mover whose collision box each geom is (-1: none)."""
        for k, body in enumerate(bodies):
            for geom in range(model.body_geomadr[body],
                              model.body_geomadr[body] + model.body_geomnum[body]):
                if model.geom_conaffinity[geom] == _MOVER_CONAFFINITY:
                    self.of_geom[geom] = k
        self._mover_of: list[int] = self.of_geom.tolist()

    def __len__(self) -> int:
        return len(self.mocap)

    def set_poses(self, data: mujoco.MjData, poses: Sequence[tuple[float, float, float]]) -> None:
        """Place mover k at ``poses[k]`` = (x, y, yaw) (m, rad) on the floor."""
        if len(poses) != len(self.mocap):
            raise ValueError(f"{len(poses)} poses for {len(self.mocap)} movers")
        if len(poses) == 0:
            return
        data.mocap_pos[self.mocap] = [(x, y, height) for (x, y, _), height
                                      in zip(poses, self._heights, strict=True)]
        data.mocap_quat[self.mocap] = [(math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
                                       for _, _, yaw in poses]

    def touched(self, data: mujoco.MjData, footprint: int) -> int | None:
        """The mover whose collision box touches geom ``footprint`` (the lowest index if
        several do), or None."""
        if data.ncon == 0 or not len(self.mocap):
            return None
        mover_of = self._mover_of
        hit = [k for geom in contact_partners(data, footprint) if (k := mover_of[geom]) >= 0]
        return min(hit) if hit else None


def contact_partners(data: mujoco.MjData, geom: int) -> list[int]:
    """The geoms in contact with geom ``geom`` in ``data``, one per contact (the few contacts
    of a step read as plain integers: faster than array masks this small)."""
    return [b if a == geom else a for a, b in data.contact.geom.tolist() if geom in (a, b)]


def _count(model: mujoco.MjModel, prefix: str) -> int:
    """How many movers named ``<prefix><k>...`` the model's mocap bodies hold."""
    names = {model.body(b).name for b in range(model.nbody) if model.body_mocapid[b] >= 0}
    return len({name[len(prefix):].split("/", 1)[0] for name in names
                if name.startswith(prefix)})


__all__ = ["PEDESTRIAN_HEIGHT", "PEDESTRIAN_SIZE", "SLICES", "STACKS", "Movers", "add_movers",
           "contact_partners", "pedestrian_name", "vehicle_name"]
