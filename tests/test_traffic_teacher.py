"""The scripted follower and the privileged teacher among traffic (:mod:`crllk.tasks.follower`,
:mod:`crllk.tasks.teacher`): keeping the headway behind a slow vehicle, waiting for a crossing
pedestrian and passing one that holds beside the robot, unchanged without movers; and the
movers in the state features of tasks with traffic (names, values, exact resume). Real MuJoCo
throughout."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from crllk.envs.batched import make_env
from crllk.maps.routes import advance, opposite_lane
from crllk.rl.models import STATE_FEATURE_SCALES, state_feature_scales
from crllk.sim import constants as C
from crllk.tasks.actions import action_duty, duty_to_action
from crllk.tasks.follower import FollowerGains, FollowerPolicy, LaneFollower, task_headway
from crllk.tasks.following import FRONT
from crllk.tasks.lane_keeping import MOVER_RANGE, MOVERS_REPORTED, state_feature_names
from crllk.tasks.teacher import Teacher
from crllk.tasks.traffic import YIELD_GAP

STILL = np.zeros(2)
MOVER_NAMES = [f"mover_{field}_{k}" for k in range(1, MOVERS_REPORTED + 1)
               for field in ("distance", "lateral_left", "lateral_right", "speed")]
NONE = [MOVER_RANGE, 0.0, 0.0, 0.0]
"""A mover slot with no mover."""
FAR_AWAY = 10**6
"""A pedestrian's wait (control steps) that keeps it at the roadside throughout a test."""


@pytest.fixture
def load(load_task):
    """``crllk.load`` with wheel duties as actions and state observations."""
    def make(task, seed=0, overrides=None):
        return load_task(task, observation="state", action="duty", seed=seed,
                         overrides=overrides)

    return make


def follower_of(env) -> LaneFollower:
    """The follower of the env's task, keeping a little more than its headway bound."""
    config = env.task.config
    return LaneFollower(config.map, config.motor, headway=task_headway(config))


def west_lane(dmap, column: int):
    """The west-bound lane of tile (column, 1): the straight top row of the loop."""
    return next(ln for ln in dmap.tile_lanes(column, 1)
                if math.isclose(abs(ln.start_heading), math.pi, abs_tol=1e-9))


def place_robot(env, x: float, y: float, yaw: float) -> None:
    """The robot at rest at axle pose (x, y, yaw)."""
    env.physics.set_pose(x, y, yaw)
    env.physics.forward()


def features(env) -> dict[str, float]:
    """The state features by name."""
    names = state_feature_names(env.task.config)
    return dict(zip(names, env.task.state_feature_list(env.physics), strict=True))


def place_vehicles(env, vehicles: list[list]) -> None:
    """Set the vehicles' state ([lane index, along, cruise speed]) and bodies."""
    state = env.task.episode.traffic
    state["vehicles"] = vehicles
    env.physics.set_mover_poses(env.task.traffic.poses(state))
    env.physics.forward()
    env.task.after_step(env.physics)


def behind_slow_vehicle(env, gap: float, speed: float) -> None:
    """The robot at rest on the top row's lane centre, vehicle 0 ``gap`` (m) ahead of its
    front cruising at ``speed`` (m/s), vehicle 1 standing in the other lane three tiles on."""
    dmap = env.task.map
    lane = west_lane(dmap, 5)
    place_robot(env, *lane.point_at(0.05))
    ahead, along = advance(dmap, lane, 0.05, gap + C.FOOTPRINT_LENGTH)
    place_vehicles(env, [[dmap.lanes.index(ahead), along, speed],
                         [dmap.lanes.index(opposite_lane(dmap, west_lane(dmap, 2))), 0.0, 0.0]])


def test_follower_keeps_the_headway_behind_a_slow_vehicle(load):
    """Behind a vehicle cruising at 0.1 m/s, the follower closes up to it and follows for 300
    steps with its gap above the headway bound: no collision, cost_headway 0 on every step.
    Blind to it, it breaks the bound."""
    bound = load("traffic_loop").task.config.traffic.headway
    for aware in (True, False):
        env = load("traffic_loop", seed=2)
        env.reset()
        behind_slow_vehicle(env, 0.6, 0.1)
        follower = follower_of(env)
        gaps, costs = [], []
        for _ in range(300):
            ts = env.step(follower.duty(env.physics, env.task.movers if aware else ()))
            costs.append(float(ts.observation["cost_headway"]))
            pose = env.task.lane_pose
            gaps.append(env.task.traffic.headway(env.task.episode.traffic, pose.lane,
                                                 pose.along))
            if ts.last():
                break
        if aware:
            assert len(costs) == 300 and env.task.outcome.termination is None
            assert max(costs) == 0.0
            assert min(gaps) > bound
            assert max(gaps[-100:]) < 0.6  # it closed up: following, not hanging back
        else:
            assert max(costs) == 1.0


def crossing_scene(env, side: int, walked: float, speed: float, axle_x: float) -> None:
    """The robot at rest, heading west on the top row's lane centre with its axle at
    ``axle_x``; pedestrian 0 (the crossing of tile [3, 1]) ``walked`` (m) from ``side`` at
    ``speed`` (m/s) without waiting, the other pedestrians standing at their roadsides."""
    lane = west_lane(env.task.map, 3)
    _x, y, yaw = lane.point_at(0.0)
    place_robot(env, axle_x, y, yaw)
    pedestrians = env.task.episode.traffic["pedestrians"]
    pedestrians[0] = [side, walked, speed, 0, 0]
    for pedestrian in pedestrians[1:]:
        pedestrian[3] = FAR_AWAY
    env.physics.set_mover_poses(env.task.traffic.poses(env.task.episode.traffic))
    env.physics.forward()
    env.task.after_step(env.physics)


def test_follower_waits_for_a_crossing_pedestrian_and_passes_after(load):
    """A duckie walks into the robot's lane 0.7 m ahead: the follower stops short of its
    crossing, then drives on once it has crossed, without collision. Blind to it, it runs
    into the duckie."""
    for aware in (True, False):
        env = load("pedestrian_loop", seed=0)
        env.reset()
        crossing = env.task.traffic.crossings[0]
        line = crossing.centre[0]
        crossing_scene(env, 1, 0.0, 0.08, line + 0.7)  # side 1: on the robot's right
        follower = follower_of(env)
        speeds, fronts = [], []
        for _ in range(400):
            ts = env.step(follower.duty(env.physics, env.task.movers if aware else ()))
            x, _y, _yaw = env.physics.pose()
            speeds.append(env.physics.forward_speed())
            fronts.append(x - FRONT)
            if ts.last():
                break
        if aware:
            assert env.task.outcome.termination is None
            stopped = [front for front, v in zip(fronts, speeds, strict=True) if abs(v) < 0.01]
            assert stopped and min(stopped) > line + 0.05  # waited short of the crossing
            assert fronts[-1] < line - 0.5  # and passed it
        else:
            assert env.task.outcome.termination == "collision"
            assert env.task.hit_mover == 0


@pytest.mark.parametrize("ahead", [0.3, 0.4, 0.5])
def test_continuous_actions_cannot_wait_for_a_duckie_crossing_close_ahead(load, ahead):
    """A duckie walks into the robot's lane from its right ``ahead`` (m) in front, at 0.08
    m/s: the follower answering in wheel duties, or in the nearest stoppable actions, stops
    and lets it cross; answering in the nearest continuous actions, whose least velocity still
    drives forward, it creeps into the duckie. Why the continuous teacher collides on
    pedestrian_loop."""
    for action in ("duty", "stoppable", "continuous"):
        env = load("pedestrian_loop", seed=0)
        env.reset()
        crossing_scene(env, 1, 0.0, 0.08, env.task.traffic.crossings[0].centre[0] + ahead)
        follower = follower_of(env)
        speeds = []
        for _ in range(400):
            duty = follower.duty(env.physics, env.task.movers)
            if action != "duty":
                duty = np.array(action_duty(action, duty_to_action(action, duty)))
            ts = env.step(duty)
            speeds.append(env.physics.forward_speed())
            if ts.last():
                break
        if action != "continuous":
            assert env.task.outcome.termination is None and min(speeds) < 0.01
        else:
            assert env.task.outcome.termination == "collision" and env.task.hit_mover == 0
            assert min(speeds[20:-1]) > 0.03  # never stood still before the collision


def test_a_pedestrian_holding_beside_the_robot_lets_it_pass(load):
    """The robot standing with its front on a duckie's crossing line, the duckie walking up to
    its side: the duckie holds beside it, the follower drives on past it (the duckie is not in
    its path: ``path_margin`` < YIELD_GAP), then the duckie crosses. Neither waits for the
    other for good."""
    assert FollowerGains.path_margin < YIELD_GAP
    env = load("pedestrian_loop", seed=0)
    env.reset()
    crossing = env.task.traffic.crossings[0]
    line = crossing.centre[0]
    crossing_scene(env, 0, 0.3, 0.15, line + FRONT)  # side 0: towards the robot's left
    follower = follower_of(env)
    pedestrian = env.task.episode.traffic["pedestrians"][0]
    held = 0
    for _ in range(300):
        before = pedestrian[1]
        assert not env.step(follower.duty(env.physics, env.task.movers)).last()
        held += pedestrian[1] == before and pedestrian[4] == 0
    x, _y, _yaw = env.physics.pose()
    assert x < line - 0.5
    assert held > 0
    assert pedestrian[4] == 1  # it crossed


def test_a_pedestrian_holding_diagonally_ahead_of_the_robot_lets_it_pass(load):
    """The robot at rest with its front 2-3 cm short of a duckie walking in from its right:
    the duckie holds diagonally ahead of its front corner, inside the path's margin but
    outside the robot's width; the follower (which counts standing movers only within its
    width) drives on past it without touching it, then the duckie crosses. With the margin for
    standing movers too, each waited for the other for good."""
    for gap in (0.024, 0.026, 0.028):
        env = load("pedestrian_loop", seed=0)
        env.reset()
        line = env.task.traffic.crossings[0].centre[0]
        crossing_scene(env, 1, 0.0, 0.15, line + 0.03 + gap + FRONT)
        follower = follower_of(env)
        start = env.physics.pose()[0]
        pedestrian = env.task.episode.traffic["pedestrians"][0]
        for _ in range(400):
            assert not env.step(follower.duty(env.physics, env.task.movers)).last(), gap
        assert start - env.physics.pose()[0] > 1.0, gap  # it drove on
        assert pedestrian[4] >= 1, gap  # and the duckie crossed


def test_without_movers_in_its_path_the_follower_is_unchanged(load):
    """No mover in its path, the follower's duties are those of the follower without movers
    and without a headway bound, bit for bit: on small_loop, and on traffic_loop with both
    vehicles coming the other way in the other lane, passing the robot."""
    for task in ("small_loop", "traffic_loop"):
        env = load(task, seed=1)
        env.reset()
        if task == "traffic_loop":
            dmap = env.task.map
            place_robot(env, *west_lane(dmap, 5).point_at(0.05))
            place_vehicles(env, [[dmap.lanes.index(opposite_lane(dmap, west_lane(dmap, k))),
                                  0.0, 0.2] for k in (3, 2)])
        config = env.task.config
        plain = LaneFollower(config.map, config.motor)
        follower = follower_of(env)
        for _ in range(120):
            duty = plain.duty(env.physics)
            assert np.array_equal(follower.duty(env.physics, env.task.movers), duty)
            assert not env.step(duty).last()


def test_the_teacher_follows_the_movers_in_the_batched_env():
    """The batched env's teacher action is the teacher's answer among the task's movers;
    driving its own actions on traffic_loop it neither collides nor breaks the headway."""
    env = make_env("traffic_loop", num_envs=3, observation="state", action="duty", seed=4,
                   teacher=True, overrides={"horizon": 200})
    try:
        teachers = [Teacher(env.config, task.obstacles, "duty") for task in env.tasks]
        td = env.reset()
        for _ in range(200):
            expected = [t.action(p, task.movers)
                        for t, p, task in zip(teachers, env.physics, env.tasks, strict=True)]
            np.testing.assert_array_equal(td["teacher_action"].numpy(),
                                          np.stack(expected).astype(np.float32))
            td["action"] = td["teacher_action"]
            stepped, td = env.step_and_maybe_reset(td)
            assert not stepped["next", "terminated"].any()
            assert not stepped["next", "cost_headway"].any()
    finally:
        env.close()


# ----- the state features ---------------------------------------------------------------------

@pytest.mark.parametrize("task", ["traffic_loop", "pedestrian_loop"])
def test_traffic_tasks_report_the_movers_last(load, task):
    """With traffic, the state ends in the movers' slots, named and scaled; the entries before
    them are those of the task without traffic."""
    env = load(task)
    config = env.task.config
    names = state_feature_names(config)
    assert names[-len(MOVER_NAMES):] == MOVER_NAMES
    assert names[:-len(MOVER_NAMES)] == state_feature_names(
        dataclasses.replace(config, traffic=None))
    assert env.reset().observation["state"].shape == (len(names),)
    expected = [STATE_FEATURE_SCALES[prefix] for prefix in
                ("mover_distance", "mover_lateral", "mover_lateral", "mover_speed")]
    assert state_feature_scales(MOVER_NAMES).tolist() == pytest.approx(
        expected * MOVERS_REPORTED)


@pytest.mark.parametrize("task", ["small_loop", "obstacle_loop"])
def test_tasks_without_traffic_keep_their_features(load, task):
    """Without traffic the state is what it always was: the same names, in the same order."""
    env = load(task)
    names = state_feature_names(env.task.config)
    assert names == ["lateral_offset", "heading_error_sin", "heading_error_cos",
                     "forward_speed", "yaw_rate", "curvature_0.15m", "curvature_0.3m",
                     "curvature_0.6m",
                     *(f"obstacle_{field}_{k}" for k in (1, 2)
                       for field in ("distance", "lateral_left", "lateral_right")),
                     *(f"duty_{side}_t-{k}" for k in range(5) for side in ("left", "right"))]
    assert env.reset().observation["state"].shape == (len(names),)


def test_pedestrians_at_the_roadside_are_not_reported(load):
    """Duckies waiting beside the road are in no lane: every mover slot reads 'none'."""
    for seed in range(3):
        env = load("pedestrian_loop", seed=seed)
        env.reset()
        values = features(env)
        assert [values[name] for name in MOVER_NAMES] == NONE * MOVERS_REPORTED


def test_the_vehicle_ahead_is_reported(load):
    """The vehicle 0.4 m ahead, driving at 0.1 m/s: slot 1 holds its distance from the axle,
    its edges either side of the lane centre and its speed along the lane; the vehicle in the
    other lane is not in the robot's lane, so slot 2 reads 'none'."""
    env = load("traffic_loop", seed=2)
    env.reset()
    behind_slow_vehicle(env, 0.4, 0.1)
    env.step(STILL)
    values = features(env)
    assert all(math.isfinite(v) for v in values.values())
    assert values["mover_distance_1"] == pytest.approx(0.4 + 0.1 / 30 + FRONT, abs=0.01)
    assert values["mover_lateral_left_1"] == pytest.approx(-C.FOOTPRINT_WIDTH / 2, abs=0.01)
    assert values["mover_lateral_right_1"] == pytest.approx(C.FOOTPRINT_WIDTH / 2, abs=0.01)
    assert values["mover_speed_1"] == pytest.approx(0.1, abs=1e-6)
    assert [values[name] for name in MOVER_NAMES[4:]] == NONE


def test_a_crossing_pedestrian_is_reported_without_speed_along_the_lane(load):
    """A duckie walking across the robot's lane ahead: reported at the crossing's distance,
    its edges inside the lane, moving across it (no speed along it)."""
    env = load("pedestrian_loop", seed=0)
    env.reset()
    line = env.task.traffic.crossings[0].centre[0]
    crossing_scene(env, 1, 0.2, 0.1, line + 0.8)
    env.step(STILL)
    values = features(env)
    assert values["mover_distance_1"] == pytest.approx(0.8 - 0.03, abs=0.01)
    assert -0.105 < values["mover_lateral_left_1"] < values["mover_lateral_right_1"]
    assert values["mover_speed_1"] == pytest.approx(0.0, abs=1e-9)


def test_restored_env_replays_the_mover_features(tmp_path):
    """A batched traffic_loop env restored from a snapshot (through ``torch.save`` and
    ``torch.load`` with ``weights_only``) continues with the same state features bit for bit,
    the movers' speeds included, resets included; the follower drives both."""
    envs = [make_env("traffic_loop", num_envs=2, observation="state", action="duty", seed=s,
                     overrides={"horizon": 60}) for s in (5, 99)]
    original, restored = envs
    try:
        speeds = [state_feature_names(original.config).index(f"mover_speed_{k}")
                  for k in range(1, MOVERS_REPORTED + 1)]
        policy = FollowerPolicy(original)
        td = original.reset()
        for _ in range(40):
            _, td = original.step_and_maybe_reset(policy(td))
        torch.save(original.sim_state(), tmp_path / "env.pt")
        carried = td.clone()
        expected = []
        for _ in range(40):
            step, td = original.step_and_maybe_reset(policy(td))
            expected.append(step["next", "state"])
        restored.reset()
        restored.load_sim_state(torch.load(tmp_path / "env.pt", weights_only=True))
        td, policy = carried, FollowerPolicy(restored)
        for k in range(40):
            step, td = restored.step_and_maybe_reset(policy(td))
            assert torch.equal(step["next", "state"], expected[k]), k
        assert torch.stack(expected)[..., speeds].abs().max() > 0.05
    finally:
        for env in envs:
            env.close()


def test_the_follower_keeps_the_headway_bound_only_where_it_is_constrained():
    """5 cm beyond traffic.headway on traffic_loop, which constrains the headway; the plain
    following gap on pedestrian_loop, whose traffic section has a headway setting but no
    headway constraint, and on small_loop, which has no traffic."""
    from crllk.tasks.config import load_task_config
    from crllk.tasks.follower import task_headway
    from crllk.tasks.following import FOLLOW_GAP

    assert task_headway(load_task_config("traffic_loop")) == 0.3
    assert task_headway(load_task_config("pedestrian_loop")) is None
    assert task_headway(load_task_config("small_loop")) is None
    config = load_task_config("pedestrian_loop")
    assert LaneFollower(config.map, config.motor, headway=task_headway(config)).keep == FOLLOW_GAP
