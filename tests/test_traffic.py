"""Traffic (:mod:`crllk.tasks.traffic`, :mod:`crllk.sim.movers`): geometry probes of the movers'
paths, collisions with them, their yielding, the headway signal, determinism, exact resume,
culling of moving bodies and the checks of the ``traffic`` setting. Real MuJoCo throughout."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_runs import assert_same_runs, read_rows, run_in_process

from crllk.analysis.recording_picture import series
from crllk.envs.batched import make_env
from crllk.errors import ConfigError
from crllk.evaluation.report import breakdown, episode_rows
from crllk.maps.obstacles import footprint_gap
from crllk.maps.routes import advance, opposite_lane
from crllk.recording.recorder import read_recording, record_episodes
from crllk.rl.rollout import run_episodes
from crllk.sim import constants as C
from crllk.tasks.config import load_task_config
from crllk.tasks.follower import FollowerPolicy
from crllk.tasks.traffic import FOLLOW_GAP, ROADSIDE, duckiebot_box, pedestrian_box

REAL_MAPS = Path(__file__).parent / "data" / "real_maps" / "gym-duckietown"
STILL = np.zeros(2)
"""Both wheel duties 0: standing still."""
FORWARD = np.array([0.5, 0.5])


@pytest.fixture
def load(load_task):
    """``crllk.load`` with wheel duties as actions; renderers released after the test."""
    def make(task, seed=0, observation="state", overrides=None):
        return load_task(task, observation=observation, action="duty", seed=seed,
                         overrides=overrides)

    return make


def mover_poses(env) -> list[tuple[float, float, float]]:
    """(x, y, yaw) of each mover's body as MuJoCo holds it."""
    out = []
    for slot in env.physics.movers.mocap:
        x, y, _ = env.physics.data.mocap_pos[slot]
        w, _, _, z = env.physics.data.mocap_quat[slot]
        out.append((float(x), float(y), 2 * math.atan2(z, w)))
    return out


def place_vehicles(env, vehicles: list[list]) -> None:
    """Set the vehicles' state ([lane index, along, cruise speed]) and bodies."""
    state = env.task.episode.traffic
    state["vehicles"] = vehicles
    env.physics.set_mover_poses(env.task.traffic.poses(state))
    env.physics.forward()


# ----- geometry probes of the paths ---------------------------------------------------------

def test_vehicles_ride_the_lane_centres(load):
    """Over 400 steps of three seeds, each vehicle's body stays on a lane centre (0.1 mm),
    heading along it, on the road, while the robot stands still; they go round the corners."""
    for seed in range(3):
        env = load("traffic_loop", seed=seed)
        env.reset()
        dmap = env.task.map
        tiles = set()
        for step in range(400):
            env.step(STILL)
            for x, y, yaw in mover_poses(env):
                pose = dmap.lane_pose(x, y, yaw)
                assert abs(pose.lateral) < 1e-4, (seed, step)
                assert abs(pose.heading_error) < 1e-4, (seed, step)
                assert pose.on_road
                tiles.add(pose.tile)
        assert any(dmap.tile(*tile).kind.startswith("curve") for tile in tiles)


@pytest.mark.parametrize("name", ["4way", "udem1"])
def test_vehicles_ride_through_intersections(load, name):
    """On real maps with intersections, two vehicles each way stay on lane centres for 300
    steps while the robot stands still, and the task declares no collision."""
    path = REAL_MAPS / f"{name}.yaml"
    env = load(path, seed=1, overrides={"traffic": {"vehicles": {"ahead": 2, "opposite": 2}},
                                         "horizon": 400})
    env.reset()
    dmap = env.task.map
    for _ in range(300):
        assert not env.step(STILL).last()
        for x, y, yaw in mover_poses(env):
            assert abs(dmap.lane_pose(x, y, yaw).lateral) < 1e-4


def test_vehicles_start_ahead_and_in_the_opposite_lane(load):
    """The first vehicle starts in the robot's travel direction, 0.8-2 m ahead along the
    lanes; the second in the lane of the other direction."""
    for seed in range(10):
        env = load("traffic_loop", seed=seed)
        env.reset()
        dmap = env.task.map
        robot = env.task.lane_pose
        (lane_a, along_a, _), (lane_b, along_b, _) = env.task.episode.traffic["vehicles"]
        ahead, opposite = dmap.lanes[lane_a], dmap.lanes[lane_b]
        assert dmap.direction_of(ahead) == dmap.direction_of(robot.lane)
        assert dmap.direction_of(opposite) != dmap.direction_of(robot.lane)
        reached = [advance(dmap, robot.lane, robot.along, d / 100) for d in range(80, 201)]
        assert any(lane == ahead and abs(along - along_a) < 0.01 for lane, along in reached)
        beside = [(opposite_lane(dmap, lane), along) for lane, along in reached]
        assert any(lane == opposite for lane, _ in beside)
        assert 0.0 <= along_b <= opposite.length


def test_pedestrians_cross_on_their_line_and_wait_off_the_road(load):
    """Each duckie stays on the line through its tile's centre across the road, waits off
    the road tiles, and over 600 steps some cross all the way (and turn back)."""
    env = load("pedestrian_loop", seed=4, overrides={"horizon": 700})
    env.reset()
    env.physics.set_pose(4.0, 4.0, 0.0)  # off the road, out of every duckie's way
    env.physics.forward()
    dmap, traffic = env.task.map, env.task.traffic
    crossings = traffic.crossings
    done = [0] * len(crossings)
    for _ in range(600):
        env.task.before_step(STILL, env.physics)
        env.physics.step(8)
        for k, ((x, y, _yaw), crossing) in enumerate(zip(mover_poses(env), crossings,
                                                         strict=True)):
            cx, cy = crossing.centre
            c, s = math.cos(crossing.heading), math.sin(crossing.heading)
            along_road, across = (x - cx) * c + (y - cy) * s, -(x - cx) * s + (y - cy) * c
            assert abs(along_road) < 1e-9
            assert abs(across) <= ROADSIDE + 1e-9
            _side, walked, _speed, _wait, count = env.task.episode.traffic["pedestrians"][k]
            if walked == 0.0:
                assert not dmap.is_road(x, y)
                assert abs(abs(across) - ROADSIDE) < 1e-9
            done[k] = count
    assert sum(done) >= 2


# ----- collisions and yielding --------------------------------------------------------------

def west_lane(dmap, column: int):
    """The west-bound lane of tile (column, 1): the straight top row of the loop."""
    return next(ln for ln in dmap.tile_lanes(column, 1)
                if math.isclose(abs(ln.start_heading), math.pi, abs_tol=1e-9))


def _robot_behind_first_vehicle(env, gap: float) -> None:
    """The robot at rest on the top row's lane centre, vehicle 0 stopped ``gap`` (m) ahead of
    its front, vehicle 1 stopped in the other lane beside it."""
    dmap = env.task.map
    lane = west_lane(dmap, 4)
    x, y, heading = lane.point_at(0.05)
    env.physics.set_pose(x, y, heading)
    ahead, along = advance(dmap, lane, 0.05, gap + C.FOOTPRINT_LENGTH)
    other = opposite_lane(dmap, lane)
    place_vehicles(env, [[dmap.lanes.index(ahead), along, 0.0],
                         [dmap.lanes.index(other), 0.0, 0.0]])
    env.task.after_step(env.physics)  # the task sees the new poses


def test_driving_into_a_vehicle_is_a_collision(load):
    """Driving straight into a stopped vehicle ends the episode with termination
    'collision', hit_mover 0 and cost_collision 1, still on the road."""
    env = load("traffic_loop", seed=2)
    env.reset()
    _robot_behind_first_vehicle(env, 0.15)
    steps, ts = 0, env.step(FORWARD)
    while not ts.last():
        ts, steps = env.step(FORWARD), steps + 1
    assert steps < 60
    assert env.task.outcome.termination == "collision"
    assert env.task.hit_mover == 0
    assert env.task.hit_object is None
    assert ts.observation["cost_collision"] == 1.0
    assert ts.discount == 0.0


def test_headway_signal_is_one_below_the_bound(load):
    """Standing 0.2 m behind a stopped vehicle (bound 0.3 m): cost_headway 1; 0.5 m: 0."""
    for gap, expected in ((0.2, 1.0), (0.5, 0.0)):
        env = load("traffic_loop", seed=2)
        env.reset()
        _robot_behind_first_vehicle(env, gap)
        ts = env.step(STILL)
        assert ts.observation["cost_headway"] == expected, gap
        measured = env.task.traffic.headway(env.task.episode.traffic, env.task.lane_pose.lane,
                                            env.task.lane_pose.along)
        assert measured == pytest.approx(gap, abs=0.01)


def test_vehicles_stop_behind_the_robot(load):
    """A vehicle that comes up behind the standing robot stops FOLLOW_GAP short of it: no
    collision in 300 steps."""
    env = load("traffic_loop", seed=1)
    env.reset()
    dmap = env.task.map
    x, y, yaw = west_lane(dmap, 3).point_at(0.3)
    env.physics.set_pose(x, y, yaw)
    far = opposite_lane(dmap, west_lane(dmap, 2))
    place_vehicles(env, [[dmap.lanes.index(west_lane(dmap, 4)), 0.0, 0.2],
                         [dmap.lanes.index(far), 0.0, 0.0]])
    for _ in range(300):
        ts = env.step(STILL)
        assert not ts.last()
    x, y, yaw = env.physics.pose()
    gap = footprint_gap(duckiebot_box(*mover_poses(env)[0]), duckiebot_box(x, y, yaw))
    assert FOLLOW_GAP - 1e-3 < gap < 1.2 * FOLLOW_GAP


def test_pedestrians_do_not_walk_into_the_robot(load):
    """The robot standing on a crossing: its duckie walks up to it and waits, no collision."""
    env = load("pedestrian_loop", seed=0, overrides={"horizon": 700})
    env.reset()
    traffic, state = env.task.traffic, env.task.episode.traffic
    crossing = traffic.crossings[0]
    x, y, heading = crossing.point_at(crossing.reach - 0.117, 0)  # in the lane of side 0
    env.physics.set_pose(x, y, heading - math.pi / 2)
    env.physics.forward()
    state["pedestrians"][0] = [0, 0.0, 0.15, 0, 0]
    for _ in range(300):
        ts = env.step(STILL)
        assert not ts.last()
    px, py, pyaw = mover_poses(env)[0]
    rx, ry, ryaw = env.physics.pose()
    assert 0.0 < footprint_gap(pedestrian_box(px, py, pyaw), duckiebot_box(rx, ry, ryaw)) < 0.05
    assert state["pedestrians"][0][1] > 0.0


# ----- determinism and resume ---------------------------------------------------------------

@pytest.mark.parametrize("task", ["traffic_loop", "pedestrian_loop"])
def test_same_seed_same_traffic_and_seeds_differ(load, task):
    """Same seed: the same movers, step for step; another seed: other movers."""
    runs = []
    for seed in (5, 5, 6):
        env = load(task, seed=seed)
        env.reset()
        runs.append([mover_poses(env)] + [(env.step(FORWARD), mover_poses(env))[1]
                                          for _ in range(30)])
    assert runs[0] == runs[1]
    assert runs[0] != runs[2]


def test_an_episode_draws_one_number_for_its_traffic(load):
    """However the episode went, the next episode starts where it would have: the traffic
    takes one draw per episode from the task's generator."""
    starts = []
    for action in (STILL, np.array([0.4, 0.2])):
        env = load("pedestrian_loop", seed=9)
        env.reset()
        for _ in range(20):
            if env.step(action).last():
                break
        env.reset()
        starts.append((env.physics.pose(), env.task.episode.traffic))
    assert starts[0] == starts[1]


@pytest.mark.parametrize(("task", "observation"), [("traffic_loop", "state"),
                                                   ("pedestrian_loop", "state"),
                                                   ("traffic_loop", "pixels")])
def test_restored_env_replays_the_traffic(tmp_path, task, observation):
    """A batched env restored from a snapshot taken mid-run (through ``torch.save`` and
    ``torch.load`` with ``weights_only``) replays the original's next steps bit for bit, resets
    included, movers and all."""
    generator = torch.Generator().manual_seed(3)
    actions = torch.randint(0, 3, (70, 2), generator=generator)
    envs = [make_env(task, num_envs=2, observation=observation, seed=s,
                     overrides={"horizon": 40}) for s in (0, 99)]
    original, restored = envs
    try:
        td = original.reset()
        for action in actions[:30]:
            td["action"] = action
            _, td = original.step_and_maybe_reset(td)
        torch.save(original.sim_state(), tmp_path / "env.pt")
        carried = td.clone()
        expected, poses = [], []
        for action in actions[30:]:
            td["action"] = action
            step, td = original.step_and_maybe_reset(td)
            expected.append(step)
            poses.append(original.physics[0].data.mocap_pos.copy())
        restored.reset()
        restored.load_sim_state(torch.load(tmp_path / "env.pt", weights_only=True))
        td = carried
        for k, action in enumerate(actions[30:]):
            td["action"] = action
            step, td = restored.step_and_maybe_reset(td)
            for key in ("reward", "cost_collision", "done", observation):
                assert torch.equal(step["next", key], expected[k]["next", key]), (k, key)
            np.testing.assert_array_equal(restored.physics[0].data.mocap_pos, poses[k])
        assert torch.stack([e["next", "done"] for e in expected]).any()
    finally:
        for env in envs:
            env.close()


# ----- the camera draws them ----------------------------------------------------------------

def test_a_vehicle_ahead_is_drawn_and_culling_keeps_it(load):
    """A vehicle 0.4 m ahead changes the camera image; the culled scene keeps it and gives the
    full scene's image; moved behind the robot it is left out."""
    env = load("traffic_loop", seed=2, observation="pixels")
    env.reset()
    _robot_behind_first_vehicle(env, 0.4)
    physics = env.physics
    with_vehicle = physics.render_camera(60, 80)
    culler = physics._culler(C.CAMERA, 60, 80)
    vehicle_geoms = {g for g in range(physics.model.ngeom)
                     if physics.model.geom_bodyid[g] in _vehicle_bodies(physics, 0)
                     and physics.model.geom_group[g] == 1}
    assert not vehicle_geoms & set(culler.outside(physics.data.ptr).tolist())
    x, y, yaw = physics.pose()
    state = env.task.episode.traffic
    state["vehicles"][0][1] = 0.0
    physics.set_mover_poses([(x - 0.6 * math.cos(yaw), y - 0.6 * math.sin(yaw), yaw),
                             env.task.traffic.poses(state)[1]])
    physics.forward()
    assert vehicle_geoms <= set(culler.outside(physics.data.ptr).tolist())
    assert not np.array_equal(physics.render_camera(60, 80), with_vehicle)


def _vehicle_bodies(physics, index: int) -> set[int]:
    model = physics.model
    prefix = f"{C.VEHICLE_PREFIX}{index}/"
    return {b for b in range(model.nbody) if model.id2name(b, "body").startswith(prefix)}


# ----- the traffic setting ------------------------------------------------------------------

@pytest.mark.parametrize(("overrides", "field"), [
    ({"traffic": {"vehicles": {"ahead": -1}}}, "traffic.vehicles.ahead"),
    ({"traffic": {"vehicles": {"speed": [0.2, 0.1]}}}, "traffic.vehicles.speed"),
    ({"traffic": {"vehicles": {"distance": [0.1, 1.0]}}}, "traffic.vehicles.distance"),
    ({"traffic": {"vehicles": {"ahead": 4, "distance": [0.8, 1.5]}}},
     "traffic.vehicles.distance"),
    ({"traffic": {"cars": 2}}, "traffic.cars"),
    ({"traffic": {"headway": 0}}, "traffic.headway"),
    ({"traffic": {"pedestrians": {"crossings": [[1, 1]]}}}, "traffic.pedestrians.crossings[0]"),
    ({"traffic": {"pedestrians": {"crossings": [[3, 1], [9, 9]]}}},
     "traffic.pedestrians.crossings[1]"),
    ({"traffic": {"pedestrians": {"wait": "soon"}}}, "traffic.pedestrians.wait"),
    ({"traffic": None, "constraints": ["lane", "collision", "headway"]}, "constraints[2]"),
])
def test_bad_traffic_settings_name_the_field(overrides, field):
    with pytest.raises(ConfigError) as caught:
        load_task_config("traffic_loop", overrides)
    assert f"traffic_loop.yaml: {field}: " in str(caught.value)
    assert "\n" not in str(caught.value)


def test_traffic_needs_a_road_without_obstacles():
    with pytest.raises(ConfigError, match=r"obstacle_loop.yaml: traffic: movers do not avoid"):
        load_task_config("obstacle_loop", {"traffic": {"vehicles": {"ahead": 1}}})


# ----- recordings ---------------------------------------------------------------------------

def test_recordings_show_the_movers_at_every_step(tmp_path):
    """A recorded traffic_loop episode logs both vehicles' boxes at every step, moving as
    vehicles do (at most 0.2 m/s)."""
    env = make_env("traffic_loop", observation="state", action="duty", seed=1,
                   overrides={"horizon": 20})
    report = record_episodes(env, FollowerPolicy(env), 1, tmp_path / "t.rrd")
    env.close()
    rows = series(read_recording(tmp_path / "t.rrd")["world/movers"], "Boxes3D:centers").values
    assert len(rows) == report.steps == 20
    centres = np.array([[c[:2] for c in row] for row in rows])
    assert centres.shape == (20, 2, 2)
    moved = np.linalg.norm(np.diff(centres, axis=0), axis=2)
    assert moved.max() <= 0.2 / 30 + 1e-4
    assert moved.sum() > 0.05


def test_a_stopped_traffic_run_resumes_exactly(tmp_path):
    """Training on traffic_loop (two worker processes, so the movers' state crosses the pipes
    both ways) stopped after two iterations and resumed for two more equals an uninterrupted
    run bit for bit: checkpoints (with the simulations) and metrics, J_chead included."""
    small = ["task=traffic_loop", "obs=state", "workers=2", "eval.final=false",
             "ppo.anneal_lr=false"]
    stopped = run_in_process(tmp_path / "stopped", 2, small)
    run_in_process(stopped, 4, [*small, "resume=true"])
    straight = run_in_process(tmp_path / "straight", 4, small)
    assert_same_runs(straight, stopped, 4)
    assert "J_chead" in read_rows(straight / "metrics.csv")[0]


def test_evaluation_names_the_mover_each_collision_hit():
    """The follower blind to movers runs into the vehicle ahead: the evaluation's episodes
    and breakdown name that mover."""
    env = make_env("traffic_loop", observation="state", action="duty", seed=3)
    result = run_episodes(env, FollowerPolicy(env, avoid_movers=False), 1)
    env.close()
    assert result.terminations == ["collision"]
    assert result.hit_movers == [0] and result.hit_objects == [None]
    assert episode_rows(result, "duty")[0]["hit_mover"] == 0
    assert breakdown(result)["collisions_by_mover"] == {"0": 1}


def test_distance_ahead_leaves_out_only_points_that_cannot_count():
    """The straight-line shortcut of ``distance_ahead`` gives what projecting every point gives,
    on straights and curves, near and beyond the reach."""
    from crllk.maps.routes import Route, distance_ahead
    from crllk.tasks.config import load_task_config

    dmap = load_task_config("traffic_loop").map
    rng = np.random.default_rng(5)
    for _ in range(300):
        lane = dmap.lanes[int(rng.integers(len(dmap.lanes)))]
        along = float(rng.uniform(0.0, lane.length))
        x0, y0, _ = lane.point_at(along)
        points = [(x0 + float(dx), y0 + float(dy)) for dx, dy in rng.uniform(-1.6, 1.6, (12, 2))]
        points += [(-0.01, y0), (x0, -0.01), (dmap.width + 0.01, y0), (x0, dmap.height + 0.01)]
        half_width, reach = float(rng.uniform(0.05, 0.2)), float(rng.uniform(0.3, 1.2))
        route = Route(dmap, lane, along, reach)
        projected = [p for p in (route.project(x, y) for x, y in points)
                     if p is not None and abs(p.lateral) <= half_width]
        expected = min((p.distance for p in projected), default=None)
        assert distance_ahead(dmap, lane, along, points, half_width, reach) == expected
        for x, y in points:  # the lean measures give project's numbers
            full, lean = route.project(x, y), route.locate(x, y)
            assert (full is None) == (lean is None)
            if full is not None:
                distance, lateral, on = lean
                assert (distance, lateral, on.heading_at(x, y)) == tuple(full)


def test_outline_is_the_footprint_without_its_repeated_corners():
    """The traffic measures a footprint by its centre, corners and edge midpoints: the points
    of ``footprint_points(box, 3)``, each once."""
    from crllk.maps.obstacles import footprint_points
    from crllk.tasks.traffic import outline

    rng = np.random.default_rng(2)
    for x, y, yaw in rng.uniform(-4.0, 4.0, (200, 3)):
        for box in (duckiebot_box(x, y, yaw), pedestrian_box(x, y, yaw)):
            points = footprint_points(box, 3)
            assert len(points) == 13
            assert outline(box) == list(dict.fromkeys(points))  # the same floats, in order
            assert len(outline(box)) == 9


def test_headway_is_the_same_measured_afresh(load):
    """The vehicles' outlines the last step measured serve the headway only while the
    vehicles stand there: a fresh Traffic, before and after vehicle 0 moves, measures the same
    gap."""
    from crllk.tasks.traffic import Traffic

    env = load("traffic_loop", seed=2)
    env.reset()
    _robot_behind_first_vehicle(env, 0.4)
    env.step(STILL)
    task = env.task
    pose, state = task.lane_pose, task.episode.traffic
    gaps = []
    for shift in (0.0, -0.15):
        state["vehicles"][0][1] += shift
        fresh = Traffic(task.traffic.config, task.map, task.traffic.dt)
        gaps.append(task.traffic.headway(state, pose.lane, pose.along))
        assert gaps[-1] == fresh.headway(state, pose.lane, pose.along)
    assert gaps[0] == pytest.approx(0.4, abs=0.01)
    assert gaps[1] == pytest.approx(0.25, abs=0.01)


def test_shortened_reaches_give_the_full_reach_answers():
    """A vehicle looks for what is ahead only as far as it could still slow for it, and the
    headway signal only as far as its bound: the same speeds and signals as looking the whole
    LOOKAHEAD, for points placed at random and at the edges of those reaches."""
    from crllk.maps.routes import LANE_HALF_WIDTH, distance_ahead
    from crllk.tasks.follower import FollowerGains
    from crllk.tasks.following import CORRIDOR_MARGIN, FRONT, LOOKAHEAD, following_speed
    from crllk.tasks.traffic import Traffic

    config = load_task_config("traffic_loop")
    traffic = Traffic(config.traffic, config.map, config.control_timestep)
    dmap, bound = config.map, config.traffic.headway
    rng = np.random.default_rng(7)
    slowed = signalled = 0
    behind_axle = C.FOOTPRINT_LENGTH / 2 + C.FOOTPRINT_CENTRE_BEHIND_AXLE
    """From a vehicle's axle back to the rear of its footprint (m)."""
    for _ in range(400):
        lane = dmap.lanes[int(rng.integers(len(dmap.lanes)))]
        along, cruise = float(rng.uniform(0.0, lane.length)), float(rng.uniform(0.05, 0.4))
        capped = cruise
        if lane.curvature:
            capped = min(capped, math.sqrt(FollowerGains.max_lateral_acceleration
                                           / abs(lane.curvature)))
        edge = FRONT + FOLLOW_GAP + capped  # where following_speed reaches the capped speed
        gaps = [*rng.uniform(0.0, 1.3, 6).tolist(), edge, edge - 1e-12, edge + 1e-12]
        points = []
        for gap in gaps:
            ahead_lane, ahead_along = advance(dmap, lane, along, gap)
            points.append(ahead_lane.point_at(ahead_along, float(rng.uniform(-0.12, 0.12)))[:2])
        full = distance_ahead(dmap, lane, along, points, C.FOOTPRINT_WIDTH / 2 + CORRIDOR_MARGIN,
                              LOOKAHEAD)
        expected = capped
        if full is not None:
            slowed += following_speed(full - FRONT, FOLLOW_GAP) < expected
            expected = min(expected, following_speed(full - FRONT, FOLLOW_GAP))
        assert traffic._vehicle_speed(lane, along, cruise, points) == expected
        for gap in (float(rng.uniform(0.0, 0.8)), bound, bound - 1e-12, bound + 1e-12):
            # a vehicle whose rear is about ``gap`` ahead of the robot's front
            ahead_lane, ahead_along = advance(dmap, lane, along, gap + FRONT + behind_axle)
            state = {"vehicles": [[dmap.lanes.index(ahead_lane), ahead_along, 0.1]]}
            full_gap = distance_ahead(dmap, lane, along, traffic._vehicle_outlines(state)[0],
                                      LANE_HALF_WIDTH, max(LOOKAHEAD, bound) + FRONT)
            signal = full_gap is not None and full_gap - FRONT < bound
            signalled += signal
            assert traffic.within_headway(state, lane, along) == signal, (gap, full_gap)
    assert slowed > 20 and signalled > 100  # both reaches were exercised


def test_scenes_with_movers_draw_curves_coarser_and_others_as_before():
    """A scene with movers draws its curved surfaces with movers.SLICES x STACKS; a scene
    without keeps MuJoCo's defaults, so its images are unchanged."""
    import mujoco

    from crllk.sim import movers
    from crllk.tasks.config import load_task_config
    from crllk.tasks.lane_keeping import physics_of

    defaults = mujoco.MjSpec().compile().vis.quality
    for task, expected in (("traffic_loop", (movers.SLICES, movers.STACKS)),
                           ("pedestrian_loop", (movers.SLICES, movers.STACKS)),
                           ("obstacle_loop", (defaults.numslices, defaults.numstacks))):
        quality = physics_of(load_task_config(task)).model.vis.quality
        assert (quality.numslices, quality.numstacks) == expected, task
