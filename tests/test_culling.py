"""Frustum culling (:mod:`crllk.sim.culling`): the same images, bit for bit, on every task with
and without randomisation and from every camera; geometry probes of what is kept and left out;
bounding radii with worked numbers; alphas restored exactly."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch

import crllk.sim.physics as physics_module
from crllk.envs.batched import make_env
from crllk.paths import task_names
from crllk.sim import constants as C
from crllk.sim.culling import FrustumCuller, bounding_radii, cullable, hidden_geoms

CAMERAS = ((C.CAMERA, (30, 40), 2), (C.CHASE_CAMERA, (48, 64), 1),
           (C.OVERHEAD_CAMERA, (40, 40), 1))
"""The robot camera as training renders it, and the recordings' chase and overhead views."""


def _render_without_culling(physics, monkeypatch, *args, **kwargs) -> np.ndarray:
    with monkeypatch.context() as patch:
        patch.setattr(FrustumCuller, "outside", lambda self, data: physics_module._NONE)
        return physics.render_camera(*args, **kwargs)


@pytest.mark.parametrize("randomize", [None, "default"])
@pytest.mark.parametrize("task", task_names())
def test_culled_images_equal_the_full_scenes(task, randomize, monkeypatch):
    """Along random drives of four simulations (resets included), every camera's image with
    the culled scene equals the one with every geom, and culling did leave geoms out."""
    overrides = None if randomize is None else {"randomize": randomize}
    env = make_env(task, num_envs=4, seed=11, overrides=overrides)
    generator = torch.Generator().manual_seed(0)
    td, compared, left_out = env.reset(), 0, 0
    try:
        for step in range(24):
            td["action"] = torch.randint(0, 3, (4,), generator=generator)
            _, td = env.step_and_maybe_reset(td)
            if step % 6:
                continue
            for physics in env.physics:
                culler = physics._culler(C.CAMERA, 60, 80)
                left_out += len(culler.outside(physics.data.ptr))
                for camera, size, supersample in CAMERAS:
                    culled = physics.render_camera(*size, supersample, camera=camera)
                    full = _render_without_culling(physics, monkeypatch, *size, supersample,
                                                   camera=camera)
                    np.testing.assert_array_equal(culled, full, err_msg=f"{task} {camera}")
                    compared += 1
    finally:
        env.close()
    assert compared == 4 * 4 * len(CAMERAS)
    assert left_out > 0


def _probe_model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string("""
    <mujoco><worldbody>
      <camera name="eye" pos="0 0 0" xyaxes="0 -1 0 0 0 1" fovy="60"/>
      <geom name="ahead" type="sphere" size="0.1" pos="2 0 0"/>
      <geom name="behind" type="sphere" size="0.1" pos="-2 0 0"/>
      <geom name="left" type="box" size="0.1 0.1 0.1" pos="1 3 0"/>
      <geom name="edge" type="sphere" size="0.3" pos="1 0 0.8"/>
      <geom name="hidden_group" type="sphere" size="0.1" pos="-2 0 0" group="3"/>
      <geom name="clear" type="sphere" size="0.1" pos="-3 0 0" rgba="1 1 1 0"/>
      <geom name="floor" type="plane" size="1 1 0.1" pos="0 0 -5"/>
    </worldbody></mujoco>""")


def test_probes_in_view_are_kept_and_the_others_left_out():
    """The camera at the origin looks along +x (60 degree vertical field, square image): a
    sphere ahead is kept; one behind and a box far to the side are left out; a sphere whose
    centre is above the view but whose surface reaches into it is kept; geoms not drawn
    anyway (group 3, alpha 0) and planes are never reported."""
    model = _probe_model()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    camera = model.camera("eye").id
    assert cullable(model, camera)
    outside = FrustumCuller(model, camera, aspect=1.0).outside(data)
    names = {model.geom(int(i)).name for i in outside}
    assert names == {"behind", "left"}  # the edge sphere's surface is 0.19 m inside the top


def test_a_sphere_just_above_the_view_is_left_out():
    """The edge sphere's centre (1 ahead, 0.8 up) lies (0.8 − tan 30°) · cos 30° = 0.193 m
    beyond the view's top plane: radius 0.3 reaches in (kept, above); radius 0.18 does not."""
    model = _probe_model()
    model.geom_size[model.geom("edge").id, 0] = 0.18
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    outside = FrustumCuller(model, model.camera("eye").id, aspect=1.0).outside(data)
    assert "edge" in {model.geom(int(i)).name for i in outside}


def test_a_probe_moves_out_of_view_when_its_body_turns_away():
    """The same sphere ahead is left out once the camera turns round (cam_xmat of the data)."""
    model = _probe_model()
    data = mujoco.MjData(model)
    camera = model.camera("eye").id
    axes = np.column_stack([[0, 1, 0], [0, 0, 1], [1, 0, 0]]).astype(float)  # looks along -x
    mujoco.mju_mat2Quat(model.cam_quat[camera], axes.flatten())
    mujoco.mj_forward(model, data)
    outside = FrustumCuller(model, camera, aspect=1.0).outside(data)
    names = {model.geom(int(i)).name for i in outside}
    assert "ahead" in names and "behind" not in names


def test_bounding_radii_worked_numbers():
    """Box (0.3, 0.4, 1.2): 1.3; sphere 0.5: 0.5; cylinder radius 3 half-length 4: 5;
    capsule radius 2 half-length 3: 5; ellipsoid (1, 2, 0.5): 2."""
    model = mujoco.MjModel.from_xml_string("""
    <mujoco><worldbody>
      <geom type="box" size="0.3 0.4 1.2"/>
      <geom type="sphere" size="0.5"/>
      <geom type="cylinder" size="3 4"/>
      <geom type="capsule" size="2 3"/>
      <geom type="ellipsoid" size="1 2 0.5"/>
    </worldbody></mujoco>""")
    radii = bounding_radii(model, np.arange(model.ngeom))
    np.testing.assert_allclose(radii, [1.3, 0.5, 5.0, 5.0, 2.0])


def test_resized_geoms_are_measured_again():
    """A box grown after the culler was made (as scene variations resize distractor patches)
    is kept once it reaches into the view, if the culler was told it may be resized."""
    model = mujoco.MjModel.from_xml_string("""
    <mujoco><worldbody>
      <camera name="eye" pos="0 0 0" xyaxes="0 -1 0 0 0 1" fovy="60"/>
      <geom name="patch" type="box" size="0.1 0.1 0.1" pos="2 3 0"/>
    </worldbody></mujoco>""")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    patch = model.geom("patch").id
    fixed = FrustumCuller(model, 0, aspect=1.0)
    resizable = FrustumCuller(model, 0, aspect=1.0, resizable=np.array([patch]))
    assert list(resizable.outside(data)) == [patch]
    model.geom_size[patch] = [2.5, 2.5, 0.1]
    assert list(resizable.outside(data)) == []
    assert list(fixed.outside(data)) == [patch]  # measured once: why resizable is needed


def test_hidden_geoms_restores_alphas_exactly():
    model = _probe_model()
    before = model.geom_rgba.copy()
    ids = np.array([0, 2])
    with hidden_geoms(model, ids):
        assert np.all(model.geom_rgba[ids, 3] == 0)
    np.testing.assert_array_equal(model.geom_rgba, before)
    with pytest.raises(RuntimeError), hidden_geoms(model, ids):
        raise RuntimeError
    np.testing.assert_array_equal(model.geom_rgba, before)
