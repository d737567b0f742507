"""Obstacles in the lane frame: which objects are on the road, the state features that report
the nearest ones ahead, and spawns in front of obstacles. Probes on obstacle_loop's real map."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import crllk
from crllk.errors import ConfigError
from crllk.maps import load_map
from crllk.maps.obstacles import ObstacleIndex, road_band
from crllk.tasks.lane_keeping import (
    OBSTACLE_RANGE,
    OBSTACLES_REPORTED,
    _footprint_gap,
    state_feature_names,
)

DUCKIE_TOP, CONE_RIGHT, CONE_LEFT, DUCKIE_CURVE, DUCKIEBOT, BARRIER, DUCKIE_BORDER = range(7)
"""obstacle_loop's objects, in the order of its task file."""


@pytest.fixture(scope="module")
def dmap():
    return load_map("obstacle_loop")


@pytest.fixture(scope="module")
def index(dmap):
    return ObstacleIndex(dmap)


def lane_of(dmap, column, row, entry, exit_):
    return next(ln for ln in dmap.tile_lanes(column, row) if (ln.entry, ln.exit) == (entry, exit_))


def test_objects_beside_the_road_are_left_out(index):
    """The barrier stands off the road along the west edge: no lane reports it. The others
    stand (at least partly) on road tiles."""
    assert BARRIER not in index.on_road
    assert set(index.on_road) == {DUCKIE_TOP, CONE_RIGHT, CONE_LEFT, DUCKIE_CURVE, DUCKIEBOT,
                                  DUCKIE_BORDER}


def test_lateral_extent_of_the_top_row_duckie(dmap, index):
    """The duckie at (3.5, 1.2) tiles stands 0.3 tiles (0.1755 m) south of the road centre:
    in the west-bound lane its centre is 0.1755 - 0.117 = 0.0585 m right of the lane centre,
    and in the east-bound lane 0.1755 + 0.117 = 0.2925 m left of it."""
    west = index.on_lane(lane_of(dmap, 3, 1, "E", "W"))
    east = index.on_lane(lane_of(dmap, 3, 1, "W", "E"))
    assert [o.index for o in west] == [o.index for o in east] == [DUCKIE_TOP]
    w, e = west[0], east[0]
    assert (w.lateral_left + w.lateral_right) / 2 == pytest.approx(0.0585, abs=2e-3)
    assert (e.lateral_left + e.lateral_right) / 2 == pytest.approx(-0.2925, abs=2e-3)
    # the duckie's footprint is about 0.065 x 0.045 m, rotated by 10 degrees
    assert 0.04 < w.lateral_right - w.lateral_left < 0.07
    assert 0.05 < w.along_end - w.along_start < 0.08
    left_edge, right_edge = road_band(dmap)
    assert (left_edge, right_edge) == pytest.approx((-0.4095, 0.1755))


def test_both_cones_ahead_nearest_first(dmap, index):
    """Driving north up the right column, 0.6 m before the first cone: both cones are reported,
    the right one (0.058 m right of the lane centre) first, the left one 0.059 m behind it."""
    lane = lane_of(dmap, 6, 3, "S", "N")  # the tile below the cones
    x, y, yaw = lane.point_at(0.25)
    pose = dmap.lane_pose(x, y, yaw)
    ahead = index.ahead(pose, 2, OBSTACLE_RANGE)
    assert [o.index for o in ahead] == [CONE_RIGHT, CONE_LEFT]
    first, second = ahead
    cone_half = 0.051 / 2
    assert first.distance == pytest.approx((lane.length - 0.25) + 0.2925 - cone_half, abs=2e-3)
    assert second.distance - first.distance == pytest.approx(0.0585, abs=2e-3)
    assert (first.lateral_left + first.lateral_right) / 2 == pytest.approx(0.0585, abs=2e-3)
    assert (second.lateral_left + second.lateral_right) / 2 == pytest.approx(-0.0585, abs=2e-3)


def test_other_direction_sees_the_cones_in_the_oncoming_lane(dmap, index):
    """Driving south down the same column, the cones are in the other lane: far left."""
    lane = lane_of(dmap, 6, 1, "W", "S")  # the curve above, driven clockwise
    x, y, yaw = lane.point_at(0.2)
    ahead = index.ahead(dmap.lane_pose(x, y, yaw), 2, OBSTACLE_RANGE)
    assert {o.index for o in ahead} == {CONE_RIGHT, CONE_LEFT}
    assert all(o.lateral_right < -0.1 for o in ahead)


def test_obstacles_behind_and_beyond_range_are_not_reported(dmap, index):
    """Past the cones by more than the robot's body, or 1.5 m before them, nothing is ahead
    within range on that stretch."""
    beyond = lane_of(dmap, 6, 2, "S", "N")
    x, y, yaw = beyond.point_at(0.55)  # 0.17 m past the left cone's far edge
    assert [o.index for o in index.ahead(dmap.lane_pose(x, y, yaw), 2, 0.5)] == []
    lane = lane_of(dmap, 6, 4, "W", "N")  # curve below: the cones are 1.50 and 1.56 m ahead
    x, y, yaw = lane.point_at(0.0)
    pose = dmap.lane_pose(x, y, yaw)
    assert index.ahead(pose, 2, 1.4) == []
    assert [o.index for o in index.ahead(pose, 2, 1.5)] == [CONE_RIGHT]
    assert len(index.ahead(pose, 2, 1.6)) == 2


def test_state_features_report_two_obstacles(dmap):
    """The state observation holds distance, left and right edge of the two nearest obstacles;
    an empty slot reads (range, 0, 0)."""
    env = crllk.load("obstacle_loop", observation="state", action="discrete", seed=0)
    names = state_feature_names(env.task.config)
    slots = [n for n in names if n.startswith("obstacle_")]
    assert len(slots) == 3 * OBSTACLES_REPORTED
    env.reset()
    lane = lane_of(dmap, 6, 3, "S", "N")
    env.physics.set_pose(*lane.point_at(0.25))
    env.physics.forward()
    env.task.after_step(env.physics)
    features = dict(zip(names, env.task.state_features(env.physics), strict=True))
    assert features["obstacle_distance_1"] < features["obstacle_distance_2"] < 1.0
    assert features["obstacle_lateral_left_2"] < 0 < features["obstacle_lateral_right_1"]
    empty = crllk.load("small_loop", observation="state", seed=0)
    empty.reset()
    feats = dict(zip(names, empty.task.state_features(empty.physics), strict=True))
    assert [feats[s] for s in slots] == [OBSTACLE_RANGE, 0.0, 0.0] * OBSTACLES_REPORTED


def test_spawns_keep_their_footprint_clear_of_obstacles():
    """200 spawns on obstacle_loop: the robot's footprint starts at least the clearance
    (0.25 m) from every obstacle's footprint."""
    env = crllk.load("obstacle_loop", observation="state", seed=3)
    objects = env.task.map.objects
    for _ in range(200):
        env.reset()
        x, y, yaw = env.physics.pose()
        assert min(_footprint_gap(o, x, y, yaw) for o in objects) >= 0.25


def test_footprint_gap_measures_from_the_front():
    """An object 0.3 m ahead of the axle is 0.3 - 0.066 m from the robot's front edge."""
    obj = load_map("obstacle_loop").objects[CONE_RIGHT]
    # robot facing +x, its axle 0.3 m behind the cone's near side
    gap = _footprint_gap(obj, obj.x - obj.length / 2 - 0.3, obj.y, 0.0)
    assert gap == pytest.approx(0.3 - 0.066, abs=1e-9)


def test_encounter_spawns_start_before_a_blocking_obstacle():
    """With spawn.encounters = 1 every episode starts with an obstacle ahead that blocks the
    lane (within 0.1 m of its centre line) at the encounter distance; with 0 the spawn stream
    is unchanged."""
    env = crllk.load("obstacle_loop", observation="state", seed=5,
                     overrides={"spawn": {"encounters": 1.0}})
    for _ in range(50):
        env.reset()
        assert env.task.encounter
        pose = env.task.lane_pose
        ahead = env.task.obstacles.ahead(pose, 7, 1.5)
        assert any(0.25 < o.distance < 1.2 + 0.05 and o.lateral_left < 0.1
                   and o.lateral_right > -0.1 for o in ahead), (pose, ahead)
        assert -0.25 - 1e-9 <= pose.lateral <= 0.04 + 0.05
    plain = [crllk.load("obstacle_loop", observation="state", seed=7,
                        overrides=o) for o in (None, {"spawn": {"encounters": 0.0}})]
    for a, b in zip(*(p.reset().observation["state"] for p in plain), strict=True):
        assert a == b
    assert not plain[0].task.encounter


def test_encounter_probability_is_checked():
    with pytest.raises(ConfigError, match=r"spawn.encounters.*\[0, 1\]"):
        crllk.load("obstacle_loop", observation="state", overrides={"spawn": {"encounters": 1.5}})


def test_encounters_can_favour_obstacles_on_curves():
    """obstacle_loop blocks five lanes, two of them on curves: with
    spawn.encounter_curve_weight = 4 a curve is drawn 8 of 11 times, with 1 each obstacle
    alike and by the same draws as without the setting."""
    weighted = crllk.load("obstacle_loop", observation="state", seed=2,
                          overrides={"spawn": {"encounter_curve_weight": 4.0}}).task
    assert [bool(lane.turn) for lane, _ in weighted._blocking].count(True) == 2
    assert len(weighted._blocking) == 5
    draws = 4000
    on_curves = sum(bool(weighted._encounter_obstacle()[0].turn) for _ in range(draws))
    assert on_curves / draws == pytest.approx(8 / 11, abs=0.025)  # 3.5 standard deviations
    alike, default = (crllk.load("obstacle_loop", observation="state", seed=2, overrides=o).task
                      for o in ({"spawn": {"encounter_curve_weight": 1.0}}, None))
    assert alike._encounter_weights is None
    assert ([alike._encounter_obstacle()[1].index for _ in range(50)]
            == [default._encounter_obstacle()[1].index for _ in range(50)])
    with pytest.raises(ConfigError, match=r"spawn.encounter_curve_weight: must be positive"):
        crllk.load("obstacle_loop", observation="state",
                   overrides={"spawn": {"encounter_curve_weight": 0.0}})


def test_the_trainers_curve_weight_reaches_its_training_tasks():
    from crllk.config import validate
    from crllk.training.build import build_env
    from crllk.training.compose import compose_config

    config = validate(compose_config(["task=obstacle_loop", "obs=state",
                                      "encounter_curve_weight=4"]))
    env = build_env(config, num_envs=1, seed=0, training=True)
    try:
        weights = env.tasks[0]._encounter_weights
        assert weights is not None and sorted(weights * 11) == pytest.approx([1, 1, 1, 4, 4])
    finally:
        env.close()


def test_encounter_episodes_are_truncated_at_their_own_horizon():
    """With spawn.encounter_horizon = 20, encounter episodes are truncated (not terminated)
    after 20 steps and the others run on; a value set must be positive."""
    env = crllk.make_env("obstacle_loop", num_envs=8, observation="state", action="duty",
                         seed=3, overrides={"spawn": {"encounters": 0.5, "encounter_horizon": 20}})
    td = env.reset()
    encounter = td["encounter"].reshape(-1).numpy().copy()
    assert 0 < encounter.sum() < 8
    td["action"] = torch.zeros(8, 2)  # standing still: nothing ends the episodes but time
    for _ in range(20):
        td = env.step(td)["next"]
        td["action"] = torch.zeros(8, 2)
    assert td["truncated"].reshape(-1).numpy().tolist() == encounter.tolist()
    assert not td["terminated"].any()
    with pytest.raises(ConfigError, match=r"spawn.encounter_horizon: must be positive, got -1"):
        crllk.load("obstacle_loop", observation="state",
                   overrides={"spawn": {"encounter_horizon": -1}})


def test_encounter_share_and_flag_in_the_batched_env():
    """The batched env flags encounter episodes in ``"encounter"``, about the asked share."""
    env = crllk.make_env("obstacle_loop", num_envs=64, observation="state", seed=0,
                         overrides={"spawn": {"encounters": 0.5}})
    td = env.reset()
    flags = td["encounter"].reshape(-1).numpy()
    assert flags.dtype == np.bool_
    assert 20 < flags.sum() < 44
    assert flags.tolist() == [t.encounter for t in env.tasks]
    assert "encounter" not in crllk.make_env("obstacle_loop", observation="state").reset()
    assert math.isfinite(float(td["state"].sum()))
