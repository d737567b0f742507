"""Frustum culling: the geoms a camera cannot see are left out of the scene before it is drawn.

MuJoCo puts every visible geom of the model into the scene it draws, and Mesa's software
rasteriser (llvmpipe) pays for each one's vertices even when all of them fall outside the
image: at the robot camera's 60×80 render, drawing the obstacles and the robot's own parts
behind the camera cost about a third of a frame. A geom whose bounding sphere lies wholly
outside the camera's view frustum contributes no pixel (the scene has no shadows and no
reflections), so leaving it out gives the same image, bit for bit.

A geom is left out by zeroing its alpha in the model while ``mjv_updateScene`` runs
(MuJoCo skips geoms of alpha 0) and restoring it right after (:func:`hidden_geoms`): a write
to the shared model, so scenes of one model are updated one at a time.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager

import mujoco
import numpy as np

_VISIBLE_GROUPS = tuple(np.flatnonzero(mujoco.MjvOption().geomgroup))
"""Geom groups a default ``MjvOption`` draws (the renderers use the default)."""
_MARGIN = 1e-3
"""Added to every bounding radius (m), so that rounding never drops a visible geom."""
_SLACK = 1.01
"""Factor on every bounding radius, for the same reason."""

_PLANE, _SPHERE, _CAPSULE, _ELLIPSOID, _CYLINDER, _BOX = (
    int(mujoco.mjtGeom.mjGEOM_PLANE), int(mujoco.mjtGeom.mjGEOM_SPHERE),
    int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_ELLIPSOID),
    int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_BOX))
_PERSPECTIVE = int(mujoco.mjtProjection.mjPROJ_PERSPECTIVE)


class FrustumCuller:
    """Which geoms of ``model`` lie wholly outside the view of fixed perspective camera
    ``camera_id`` drawn at ``aspect`` (width / height).

    Candidates are the geoms a default scene draws other than planes (always kept); their
    bounding spheres lie around their current world positions in the data. Their radii come
    from their sizes when the culler is made, but for the ``resizable`` geoms (boxes whose
    size scene variations rewrite), measured again on every call."""

    def __init__(self, model: mujoco.MjModel, camera_id: int, aspect: float,
                 resizable: np.ndarray | None = None):
        self.model, self.camera_id, self.aspect = model, camera_id, aspect
        drawn = np.isin(model.geom_group, _VISIBLE_GROUPS) & (model.geom_type != _PLANE)
        self.candidates = np.flatnonzero(drawn)
        self._radii = bounding_radii(model, self.candidates) * _SLACK + _MARGIN
        resizable = np.zeros(0, dtype=int) if resizable is None else resizable
        self._resizable = np.flatnonzero(np.isin(self.candidates, resizable))
        """Positions (in :attr:`candidates`) of the resizable geoms."""

    def outside(self, data: mujoco.MjData) -> np.ndarray:
        """Ids of the candidate geoms drawn with alpha > 0 that the camera cannot see."""
        model, camera, ids = self.model, self.camera_id, self.candidates
        radius = self._radii
        if self._resizable.size:
            radius = radius.copy()
            resized = bounding_radii(model, ids[self._resizable])
            radius[self._resizable] = resized * _SLACK + _MARGIN
        rotation = data.cam_xmat[camera].reshape(3, 3)
        local = (data.geom_xpos[ids] - data.cam_xpos[camera]) @ rotation  # x right, y up
        depth = -local[:, 2]  # MuJoCo cameras look along their -z axis
        half_height = math.radians(model.cam_fovy[camera]) / 2
        half_width = math.atan(math.tan(half_height) * self.aspect)
        inside = ((depth > -radius)
                  & (np.abs(local[:, 1]) * math.cos(half_height)
                     - depth * math.sin(half_height) <= radius)
                  & (np.abs(local[:, 0]) * math.cos(half_width)
                     - depth * math.sin(half_width) <= radius))
        return ids[~inside & (model.geom_rgba[ids, 3] > 0)]


def bounding_radii(model: mujoco.MjModel, ids: np.ndarray) -> np.ndarray:
    """Radius (m) of the sphere around each geom's frame origin that holds the geom, from
    its current size (meshes and other types: MuJoCo's ``geom_rbound``)."""
    size = model.geom_size[ids]
    types = model.geom_type[ids]
    by_type = {_BOX: np.linalg.norm(size, axis=1), _SPHERE: size[:, 0],
               _ELLIPSOID: size.max(axis=1), _CYLINDER: np.hypot(size[:, 0], size[:, 1]),
               _CAPSULE: size[:, 0] + size[:, 1]}
    radii = model.geom_rbound[ids].copy()
    for geom_type, radius in by_type.items():
        radii = np.where(types == geom_type, radius, radii)
    return radii


@contextmanager
def hidden_geoms(model: mujoco.MjModel, ids: np.ndarray) -> Iterator[None]:
    """Geoms ``ids`` with alpha 0 (left out of scenes updated meanwhile), then as before."""
    if ids.size == 0:
        yield
        return
    alphas = model.geom_rgba[ids, 3].copy()
    model.geom_rgba[ids, 3] = 0.0
    try:
        yield
    finally:
        model.geom_rgba[ids, 3] = alphas


def cullable(model: mujoco.MjModel, camera_id: int) -> bool:
    """Whether camera ``camera_id`` is one :class:`FrustumCuller` handles: a perspective
    camera given by its vertical field of view, in a scene where a geom out of view cannot
    change a pixel (no shadow maps, no reflecting materials)."""
    shadows = model.vis.quality.shadowsize > 0 and bool(np.any(model.light_castshadow))
    return (int(model.cam_projection[camera_id]) == _PERSPECTIVE
            and not np.any(model.cam_sensorsize[camera_id])
            and not shadows and not np.any(model.mat_reflectance > 0))


__all__ = ["FrustumCuller", "bounding_radii", "cullable", "hidden_geoms"]
