"""The Duckiebot's physics: named accessors, motor commands, camera rendering, safe stepping."""

from __future__ import annotations

import atexit
import contextlib
import logging
import math
import weakref
from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np
from dm_control import mujoco as dm_mujoco
from dm_control.mujoco.wrapper import MjModel

from crllk.images import box_average
from crllk.maps import DuckietownMap
from crllk.sim import constants as C
from crllk.sim.culling import FrustumCuller, cullable, hidden_geoms
from crllk.sim.motor import MotorConfig, clip_duty
from crllk.sim.movers import Movers, add_movers, contact_partners
from crllk.sim.scene import build_spec
from crllk.sim.variation import (
    SceneVariation,
    VariationTargets,
    appearance,
    apply_appearance,
    apply_dynamics,
    place_distractors,
)

_OPEN_RENDERERS: weakref.WeakSet[mujoco.Renderer] = weakref.WeakSet()
"""Renderers not yet closed: closed at exit while EGL is still up (their finalisers would
otherwise print EGL errors when the interpreter ends)."""


def _track(renderer: mujoco.Renderer) -> None:
    """Closes ``renderer`` at exit. The first registration comes after the first GL context's
    (which registers ``eglTerminate``), so it runs before EGL is terminated."""
    if not _OPEN_RENDERERS:
        atexit.unregister(_close_open_renderers)
        atexit.register(_close_open_renderers)
    _OPEN_RENDERERS.add(renderer)


def _close_open_renderers() -> None:
    for renderer in list(_OPEN_RENDERERS):
        with contextlib.suppress(Exception):  # exiting: nothing is left to report to
            close_renderer(renderer)


def close_renderer(renderer: mujoco.Renderer) -> None:
    """Closes ``renderer`` in its own GL context. ``mujoco.Renderer.close`` frees its textures
    and buffers in whichever context is current, which, after another renderer has drawn, is
    that renderer's: objects there with the same GL names are freed and its later images are
    garbage. So a renderer is made current before it is closed, also when its Physics is
    garbage-collected (:meth:`Physics._reload_from_data` registers the finaliser)."""
    context = getattr(renderer, "_gl_context", None)  # private in mujoco; None when closed
    if context is not None:
        context.make_current()
    renderer.close()


def _close_renderers(renderers: dict[tuple[int, int], mujoco.Renderer]) -> None:
    for renderer in renderers.values():
        close_renderer(renderer)
    renderers.clear()


log = logging.getLogger(__name__)


def check_points(x: float, y: float, yaw: float) -> list[tuple[float, float]]:
    """World (x, y) of the footprint's centre, left, right and front points for an axle pose
    (x, y, yaw). All four must lie on road tiles."""
    c, s = math.cos(yaw), math.sin(yaw)
    return [(x + c * u - s * v, y + s * u + c * v) for u, v in _CHECK_POINTS_LOCAL]


_BACK = -C.FOOTPRINT_CENTRE_BEHIND_AXLE
_CHECK_POINTS_LOCAL = ((_BACK, 0.0), (_BACK, C.FOOTPRINT_WIDTH / 2),
                       (_BACK, -C.FOOTPRINT_WIDTH / 2), (_BACK + C.FOOTPRINT_LENGTH / 2, 0.0))
"""Footprint check points in the body frame (m): centre, left, right, front."""

_WARNING_NAMES = tuple(mujoco.mjtWarning.__members__)[:mujoco.mjtWarning.mjNWARNING]
"""MuJoCo's warning kinds, in the order of ``data.warning``."""

_RK4 = int(mujoco.mjtIntegrator.mjINT_RK4)
_NONE = np.zeros(0, dtype=int)
"""No geom ids."""

_FULL_STATE = mujoco.mjtState.mjSTATE_INTEGRATION
"""Everything ``mj_step`` reads: time, qpos, qvel, act, the actuators' delay history,
warm start, ctrl, applied forces, mocap, equality flags, user data and plugin state."""


class Physics(dm_mujoco.Physics):
    """A Duckietown scene with one Duckiebot (and, with traffic, moving agents beside it).
    Lengths in m, angles in rad, times in s."""

    @classmethod
    def from_map(cls, dmap: DuckietownMap, motor: MotorConfig | None = None,
                 max_delay: float = 0.0, distractors: int = 0, vehicles: int = 0,
                 pedestrians: int = 0) -> Physics:
        """Build and compile the scene of ``dmap`` with the Duckiebot (command delays up to
        ``max_delay`` s and ``distractors`` patches possible by :meth:`set_variation`), and
        ``vehicles`` other Duckiebots and ``pedestrians`` duckies moved by
        :meth:`set_mover_poses` (:mod:`crllk.sim.movers`)."""
        spec = build_spec(dmap, motor, max_delay, distractors)
        add_movers(spec, vehicles, pedestrians)
        physics = cls.from_model(MjModel(spec.compile()))
        physics.motor = physics.nominal_motor = motor or MotorConfig()
        return physics

    def copy(self, share_model: bool = False) -> Physics:
        """A copy of the physics that keeps the motor settings and variation (dm_control's
        copy drops them). Copies that share the model know which variation it holds."""
        new = super().copy(share_model=share_model)
        new.motor, new.nominal_motor, new.trim = self.motor, self.nominal_motor, self.trim
        new.variation = self.variation
        # The model (shared, or copied as it is now) holds what this one's holds.
        new._model_variation = self._model_variation if share_model else \
            dict(self._model_variation)
        return new

    def _reload_from_data(self, data) -> None:
        super()._reload_from_data(data)
        self.motor = self.nominal_motor = MotorConfig()
        self.trim = 0.0
        """Left/right motor asymmetry of the episode (see :meth:`set_wheel_duty`)."""
        self.variation: SceneVariation | None = None
        """The episode's scene variation (None: the compiled scene)."""
        self._model_variation: dict[str, Any] = {"appearance": None, "dynamics": None,
                                                 "targets": None}
        """The variations whose appearance and dynamics the (possibly shared) model holds now,
        and the fields they change (:class:`VariationTargets`, found while the model still
        held its compiled values)."""
        self.instabilities = 0
        """Physics steps that diverged since construction."""
        self.diverged = False
        """Whether the last :meth:`step` diverged (the state was reset)."""
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        weakref.finalize(self, _close_renderers, self._renderers)
        self._cullers: dict[tuple[str, int, int], FrustumCuller | None] = {}
        """Per camera and image size: what leaves out the geoms it cannot see (None: a
        camera :func:`crllk.sim.culling.cullable` does not handle)."""
        self._obstacle_geoms = np.array(
            [i for i in range(self.model.ngeom)
             if (self.model.id2name(i, "geom") or "").startswith(C.OBSTACLE_PREFIX)], dtype=int)
        self._distractor_geoms = np.array(
            [i for i in range(self.model.ngeom)
             if (self.model.id2name(i, "geom") or "").startswith(C.DISTRACTOR_PREFIX)],
            dtype=int)
        """The distractor patches: scene variations resize them."""
        self._is_obstacle = np.zeros(self.model.ngeom, dtype=bool)
        self._is_obstacle[self._obstacle_geoms] = True
        self._footprint_geom = self.model.name2id(C.FOOTPRINT_GEOM, "geom")
        self.movers = Movers(self.model.ptr)
        """The scene's moving agents (:class:`~crllk.sim.movers.Movers`)."""
        self._root_qpos = self.model.jnt_qposadr[self.model.name2id(C.ROOT_JOINT, "joint")]
        self._root_qvel = self.model.jnt_dofadr[self.model.name2id(C.ROOT_JOINT, "joint")]
        # Raw MuJoCo handles and views into the data's buffers for the per-step hot path.
        self._mj_model, self._mj_data = self.model.ptr, self.data.ptr
        self._root_pose = self._mj_data.qpos[self._root_qpos:self._root_qpos + 7]
        self._root_velocity = self._mj_data.qvel[self._root_qvel:self._root_qvel + 6]
        self._ctrl = self._mj_data.ctrl
        self._warning_counts = self._mj_data.warning.number

    # ----- state accessors --------------------------------------------------------------
    def pose(self) -> tuple[float, float, float]:
        """Axle-centre position x, y (m) and yaw (rad, CCW from +x)."""
        px, py, _, w, x, y, z = self._root_pose.tolist()
        return px, py, math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))

    def forward_speed(self, yaw: float | None = None) -> float:
        """Speed along the robot's heading (m/s); ``yaw`` (rad) if already known."""
        if yaw is None:
            _, _, yaw = self.pose()
        vx, vy = self._root_velocity[:2].tolist()
        return vx * math.cos(yaw) + vy * math.sin(yaw)

    def yaw_rate(self) -> float:
        """Angular velocity about the vertical axis (rad/s)."""
        return float(self._root_velocity[5])

    def wheel_speeds(self) -> np.ndarray:
        """Wheel angular velocities (left, right) (rad/s), positive rolling forward."""
        return np.array([self.named.data.qvel[C.LEFT_WHEEL_JOINT][0],
                         self.named.data.qvel[C.RIGHT_WHEEL_JOINT][0]])

    def footprint_check_points(self) -> list[tuple[float, float]]:
        """World (x, y) of the footprint's centre, left, right and front points."""
        return check_points(*self.pose())

    def touches_obstacle(self) -> bool:
        """Whether the chassis footprint is in contact with any obstacle."""
        data = self._mj_data
        if data.ncon == 0 or len(self._obstacle_geoms) == 0:
            return False
        obstacle = self._is_obstacle
        return any(obstacle[geom] for geom in contact_partners(data, self._footprint_geom))

    def touched_mover(self) -> int | None:
        """The moving agent (index in :attr:`movers`: vehicles, then pedestrians) whose
        collision box the chassis footprint touches, or None."""
        return self.movers.touched(self._mj_data, self._footprint_geom)

    # ----- commands ---------------------------------------------------------------------
    def set_mover_poses(self, poses: Sequence[tuple[float, float, float]]) -> None:
        """Place moving agent k at ``poses[k]`` = (x, y, yaw) on the floor (its body frame;
        a vehicle's at its axle). Positions are current after the next step or forward."""
        self.movers.set_poses(self._mj_data, poses)

    def set_pose(self, x: float, y: float, yaw: float) -> None:
        """Place the robot at rest with its wheels on the floor."""
        a = self._root_qpos
        self.data.qpos[a:a + 3] = (x, y, C.WHEEL_RADIUS)
        self.data.qpos[a + 3:a + 7] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        self.data.qvel[:] = 0.0

    def set_wheel_duty(self, duty: Sequence[float] | np.ndarray) -> None:
        """Command duty cycles (left, right), clipped to [-1, 1], through the DB18 motor
        model."""
        left, right = clip_duty(*duty)
        if self.trim:
            left, right = clip_duty(left * (1.0 - self.trim), right * (1.0 + self.trim))
        self._ctrl[:] = (self.motor.max_speed * 0.5 * (left + right),
                         self.motor.yaw_rate_per_duty * (right - left))

    def set_variation(self, variation: SceneVariation | None) -> None:
        """Use ``variation`` (its appearance, camera and motor model) from now on; None
        restores the compiled scene and the nominal motor model."""
        self.variation = variation
        self.motor = self.nominal_motor if variation is None else variation.motor
        self.trim = 0.0 if variation is None else variation.trim
        self._use_variation("dynamics", apply_dynamics)
        self._use_variation("appearance", apply_appearance)

    def _use_variation(self, part: str, apply: Any) -> None:
        """Write ``part`` ("dynamics" or "appearance") of this physics' variation into the
        model if the model holds another one's (copies sharing the model take turns)."""
        held = self._model_variation
        if held[part] is self.variation:
            return
        if held["targets"] is None:
            held["targets"] = VariationTargets(self.model.ptr)
        apply(self.model.ptr, held["targets"], self.variation)
        held[part] = self.variation

    # ----- snapshots --------------------------------------------------------------------
    def full_state(self) -> list[float]:
        """The complete integration state (see ``_FULL_STATE``) as plain floats."""
        state = np.empty(mujoco.mj_stateSize(self.model.ptr, _FULL_STATE))
        mujoco.mj_getState(self.model.ptr, self.data.ptr, state, _FULL_STATE)
        return state.tolist()

    def set_full_state(self, state: list[float]) -> None:
        """Restore a :meth:`full_state` and recompute the position- and velocity-dependent
        fields (``mj_step1``), as a (legacy) :meth:`step` leaves them."""
        size = mujoco.mj_stateSize(self.model.ptr, _FULL_STATE)
        if len(state) != size:
            raise ValueError(f"physics state has {len(state)} values, this model needs {size}")
        self._use_variation("dynamics", apply_dynamics)
        mujoco.mj_setState(self.model.ptr, self.data.ptr, np.asarray(state, np.float64),
                           _FULL_STATE)
        mujoco.mj_step1(self.model.ptr, self.data.ptr)

    # ----- stepping ---------------------------------------------------------------------
    def step(self, nstep: int = 1) -> None:
        """Step the physics as dm_control's ``Physics.step`` does (with ``legacy_step``,
        positions and velocities are up to date afterwards), calling MuJoCo directly. As there,
        any new MuJoCo warning means the state is invalid: then the state is reset and
        :attr:`diverged` set."""
        self.diverged = False
        if self._model_variation["dynamics"] is not self.variation:
            self._use_variation("dynamics", apply_dynamics)
        before = self._warning_counts.tolist()
        self._advance(nstep)
        after = self._warning_counts.tolist()
        if after != before:  # the counters only grow
            names = [name for name, b, a in zip(_WARNING_NAMES, before, after, strict=True)
                     if a > b]
            self.diverged = True
            self.instabilities += 1
            log.warning("physics diverged (warnings raised: %s); the episode ends",
                        ", ".join(names))
            mujoco.mj_resetData(self._mj_model, self._mj_data)
            mujoco.mj_forward(self._mj_model, self._mj_data)

    def _advance(self, nstep: int) -> None:
        """``nstep`` physics steps, in the order of dm_control's ``Physics.step``."""
        model, data = self._mj_model, self._mj_data
        if not self.legacy_step:
            mujoco.mj_step(model, data, nstep)
            return
        # Legacy: mj_step1 already ran for this state (at the end of the previous step).
        if model.opt.integrator != _RK4:
            mujoco.mj_step2(model, data)
            if nstep > 1:
                mujoco.mj_step(model, data, nstep - 1)
        else:
            mujoco.mj_step(model, data, nstep)
        mujoco.mj_step1(model, data)

    # ----- rendering --------------------------------------------------------------------
    def render_camera(self, height: int, width: int, supersample: int = 1,
                      camera: str = C.CAMERA) -> np.ndarray:
        """RGB uint8 image (height, width, 3) from ``camera``, rendered ``supersample`` times
        larger per axis and box-averaged down. One renderer per size is kept and reused; geoms
        the camera cannot see are left out of its scene (:mod:`crllk.sim.culling`: the same
        image, drawn faster)."""
        if self.variation is not None or self._model_variation["appearance"] is not None:
            self._use_variation("appearance", apply_appearance)
            mujoco.mj_camlight(self._mj_model, self._mj_data)  # the variation's camera and sun
            targets = self._model_variation["targets"]
            if targets.distractor_geoms.size:
                place_distractors(self._mj_data, targets, appearance(targets, self.variation))
        size = (height * supersample, width * supersample)
        renderer = self._renderers.get(size)
        if renderer is None:
            renderer = mujoco.Renderer(self.model.ptr, *size)
            self._renderers[size] = renderer
            _track(renderer)
        culler = self._culler(camera, height, width)
        outside = culler.outside(self._mj_data) if culler is not None else _NONE
        with hidden_geoms(self._mj_model, outside):
            renderer.update_scene(self._mj_data, camera=camera)
        image = renderer.render()
        if supersample == 1:
            return image.copy()
        return box_average(image, supersample)

    def _culler(self, camera: str, height: int, width: int) -> FrustumCuller | None:
        key = (camera, height, width)
        if key not in self._cullers:
            camera_id = self.model.name2id(camera, "camera")
            self._cullers[key] = (FrustumCuller(self._mj_model, camera_id, width / height,
                                                self._distractor_geoms)
                                  if cullable(self._mj_model, camera_id) else None)
        return self._cullers[key]

    def free_renderers(self) -> None:
        """Release the GL contexts of the kept renderers."""
        _close_renderers(self._renderers)
