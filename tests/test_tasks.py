"""The task contract (after dm_control's ``suite_test``) over every task, observation and action,
plus termination, time limit, reward and spawn checks. Real MuJoCo and rendering throughout."""

from __future__ import annotations

import itertools
import math
import re

import dm_env
import numpy as np
import pytest
from dm_env import specs

import crllk
from crllk.errors import ConfigError
from crllk.paths import task_names
from crllk.tasks.config import load_task_config
from crllk.tasks.lane_keeping import ACTIONS, OBSERVATIONS, state_feature_names

TASKS = task_names()
CASES = list(itertools.product(TASKS, OBSERVATIONS, ACTIONS))
CASE_IDS = ["-".join(case) for case in CASES]
SHORT = {"horizon": 40}
"""A short horizon keeps the contract cases fast."""
ROLLOUT_STEPS = 20
DISCRETE_STRAIGHT = 2


@pytest.fixture
def make_env(load_task):
    """Build fresh environments; their renderers are released after the test."""
    def make(task, observation="state", action="discrete", seed=0, overrides=SHORT):
        return load_task(task, observation=observation, action=action, seed=seed,
                         overrides=overrides)

    return make


def test_every_paper_task_is_registered():
    """The three paper maps are shipped as tasks."""
    assert {"small_loop", "zigzag", "obstacle_loop"} <= set(TASKS)


def random_actions(action_spec, count: int, seed: int) -> list:
    """A fixed action sequence drawn from a seeded Generator within ``action_spec``."""
    rng = np.random.default_rng(seed)
    if isinstance(action_spec, specs.DiscreteArray):
        return [np.int64(a) for a in rng.integers(action_spec.num_values, size=count)]
    return list(rng.uniform(action_spec.minimum, action_spec.maximum,
                            size=(count, *action_spec.shape)))


def rollout(env, actions, mutate: bool = False) -> list[dm_env.TimeStep]:
    """Reset and step through ``actions``; with ``mutate``, scribble over each returned array
    after keeping a copy (the copies are returned)."""
    steps = []
    for i in range(len(actions) + 1):
        ts = env.reset() if i == 0 else env.step(actions[i - 1])
        kept = ts._replace(observation={k: np.array(v, copy=True)
                                        for k, v in ts.observation.items()})
        if mutate:
            for value in ts.observation.values():
                if isinstance(value, np.ndarray) and value.ndim > 0:
                    value[...] = 7
        steps.append(kept)
    return steps


def assert_same_trajectory(a: list[dm_env.TimeStep], b: list[dm_env.TimeStep]) -> None:
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        assert x.step_type == y.step_type, f"step {i}"
        assert x.reward == y.reward, f"step {i}"
        assert x.discount == y.discount, f"step {i}"
        for key in x.observation:
            np.testing.assert_array_equal(x.observation[key], y.observation[key],
                                          err_msg=f"step {i}, {key}")


# ----- the contract, over every task x observation x action ----------------------------------

@pytest.mark.parametrize(("task", "observation", "action"), CASES, ids=CASE_IDS)
def test_action_spec(make_env, task, observation, action):
    """Discrete: DiscreteArray(3). Continuous: (velocity, steering) bounded in [-1, 1]."""
    spec = make_env(task, observation, action).action_spec()
    if action == "discrete":
        assert isinstance(spec, specs.DiscreteArray)
        assert spec.num_values == 3
    else:
        assert isinstance(spec, specs.BoundedArray)
        assert not isinstance(spec, specs.DiscreteArray)
        assert spec.shape == (2,)
        np.testing.assert_array_equal(spec.minimum, [-1.0, -1.0])
        np.testing.assert_array_equal(spec.maximum, [1.0, 1.0])


@pytest.mark.parametrize(("task", "observation", "action"), CASES, ids=CASE_IDS)
def test_observations_match_spec_and_are_valid(make_env, task, observation, action):
    """On reset and every step: keys (the observation and one cost per declared constraint,
    lane and collision among them), shapes and dtypes match the spec; values are finite;
    costs are finite, non-negative and cost_collision is 0 or 1; rewards are finite."""
    env = make_env(task, observation, action, seed=11)
    obs_spec = env.observation_spec()  # before the first reset, as dm_env users ask for it
    expected = {observation, *(c.cost_key for c in env.task.config.constraints)}
    assert {"cost_lane", "cost_collision"} <= expected
    assert set(obs_spec) == expected
    if observation == "pixels":
        assert obs_spec["pixels"].shape == (30, 40, 3)
        assert obs_spec["pixels"].dtype == np.uint8
    else:
        assert obs_spec["state"].shape == (len(state_feature_names(env.task.config)),)
    steps = rollout(env, random_actions(env.action_spec(), ROLLOUT_STEPS, seed=5))
    assert env.observation_spec() == obs_spec
    for ts in steps:
        assert set(ts.observation) == expected
        for key, value in ts.observation.items():
            value = np.asarray(value)
            assert value.shape == obs_spec[key].shape, key
            assert value.dtype == obs_spec[key].dtype, key
            obs_spec[key].validate(value)
            assert np.all(np.isfinite(value)), key
        assert ts.observation["cost_lane"] >= 0.0
        assert ts.observation["cost_collision"] in (0.0, 1.0)
        if ts.first():
            assert ts.reward is None
        else:
            assert np.isfinite(ts.reward)
            assert ts.discount in (0.0, 1.0)
    assert sum(ts.mid() for ts in steps) >= 1


@pytest.mark.parametrize(("task", "observation", "action"), CASES, ids=CASE_IDS)
def test_same_seed_same_trajectory(make_env, task, observation, action):
    """Two environments with the same seed give identical observations and rewards."""
    first = make_env(task, observation, action, seed=42)
    second = make_env(task, observation, action, seed=42)
    actions = random_actions(first.action_spec(), ROLLOUT_STEPS, seed=3)
    assert_same_trajectory(rollout(first, actions), rollout(second, actions))


@pytest.mark.parametrize(("task", "observation", "action"), CASES, ids=CASE_IDS)
def test_different_seeds_different_starts(make_env, task, observation, action):
    """Different seeds spawn at different poses, and so do successive episodes."""
    poses = []
    for seed in (1, 2, 3):
        env = make_env(task, observation, action, seed=seed)
        env.reset()
        poses.append(env.physics.pose())
    env.reset()
    poses.append(env.physics.pose())
    for p, q in itertools.combinations(poses, 2):
        assert not np.allclose(p, q, atol=1e-6)


@pytest.mark.parametrize(("task", "observation", "action"), CASES, ids=CASE_IDS)
def test_observations_do_not_share_memory(make_env, task, observation, action):
    """Successive observations are separate arrays, and writing into a returned observation
    changes nothing that follows."""
    env = make_env(task, observation, action, seed=8)
    twin = make_env(task, observation, action, seed=8)
    actions = random_actions(env.action_spec(), 10, seed=4)
    assert_same_trajectory(rollout(env, actions, mutate=True), rollout(twin, actions))
    previous = env.reset().observation
    for a in actions[:3]:
        current = env.step(a).observation
        for key in current:
            assert not np.shares_memory(previous[key], current[key]), key
        previous = current


# ----- episode ends -------------------------------------------------------------------------

@pytest.mark.parametrize(("action", "command"), [("discrete", DISCRETE_STRAIGHT),
                                                  ("continuous", np.array([1.0, 0.0]))])
@pytest.mark.parametrize("seed", [0, 1])
def test_driving_off_the_road_terminates(make_env, action, command, seed):
    """Full throttle straight ahead on small_loop leaves the road before the time limit: the
    last step has discount 0, termination 'off_road', cost_collision 1 and cost_lane 10."""
    env = make_env("small_loop", "state", action, seed=seed, overrides=None)
    horizon = env.task.config.horizon
    ts = env.reset()
    steps = 0
    while not ts.last():
        ts = env.step(command)
        steps += 1
        if ts.mid():
            assert ts.discount == 1.0
            assert ts.observation["cost_collision"] == 0.0
    assert steps < horizon
    assert ts.discount == 0.0
    assert env.task.outcome.termination == "off_road"
    assert ts.observation["cost_collision"] == 1.0
    assert ts.observation["cost_lane"] == 10.0
    dmap = env.task.map
    assert not all(dmap.is_road(x, y) for x, y in env.physics.footprint_check_points())
    assert env.step(command).first()


def test_touching_an_obstacle_terminates(make_env):
    """Driving into the cone in the north-bound lane of obstacle_loop ends the episode with
    discount 0, termination 'collision' and cost_collision 1, while still on the road."""
    env = make_env("obstacle_loop", "state", "continuous", seed=0, overrides=None)
    env.reset()
    cone = max((o for o in env.task.map.objects if o.kind == "cone"), key=lambda o: o.x)
    env.physics.set_pose(cone.x - 0.06, cone.y - 0.35, math.pi / 2)
    env.physics.forward()
    ts = env.step(np.array([0.4, 0.0]))
    steps = 1
    while not ts.last():
        ts = env.step(np.array([0.4, 0.0]))
        steps += 1
    assert steps < 60
    assert ts.discount == 0.0
    assert env.task.outcome.termination == "collision"
    assert ts.observation["cost_collision"] == 1.0
    x, y, _ = env.physics.pose()
    assert env.task.map.is_road(x, y)
    assert y < cone.y


def test_time_limit_is_a_truncation(make_env):
    """Standing still for the whole horizon: step 30 of 30 is LAST with discount 1."""
    env = make_env("small_loop", "state", "continuous", seed=6, overrides={"horizon": 30})
    env.reset()
    steps = [env.step(np.zeros(2)) for _ in range(30)]
    assert all(ts.mid() and ts.discount == 1.0 for ts in steps[:-1])
    assert steps[-1].last()
    assert steps[-1].discount == 1.0
    assert env.task.outcome.termination is None
    assert all(ts.observation["cost_collision"] == 0.0 for ts in steps)
    assert env.step(np.zeros(2)).first()


def test_reward_is_progress_along_the_lane(make_env):
    """Driving straight down zigzag's long west column: the summed reward equals the distance
    moved along the lane, within 2 %."""
    env = make_env("zigzag", "state", "continuous", seed=0, overrides=None)
    env.reset()
    lane = next(ln for ln in env.task.map.tile_lanes(1, 2)
                if math.isclose(ln.start_heading, -math.pi / 2, abs_tol=1e-6))
    x0, y0, heading = lane.point_at(0.05)
    env.physics.set_pose(x0, y0, heading)
    env.physics.forward()
    env.step(np.zeros(2))  # at rest: lets the task see the new pose
    x0, y0, _ = env.physics.pose()
    total = 0.0
    for _ in range(75):
        ts = env.step(np.array([0.5, 0.0]))
        assert ts.mid()
        total += ts.reward
    x1, y1, _ = env.physics.pose()
    distance = lane.project(x1, y1).along - lane.project(x0, y0).along
    assert distance > 0.6
    assert total == pytest.approx(distance, rel=0.02)


@pytest.mark.parametrize("task", TASKS)
def test_state_length_matches_feature_names(make_env, task):
    """The state observation has one entry per name in state_feature_names(config)."""
    env = make_env(task, "state")
    names = state_feature_names(env.task.config)
    assert len(names) == len(set(names))
    assert env.reset().observation["state"].shape == (len(names),)


def test_state_length_follows_the_motor_delay(make_env):
    """A longer motor delay keeps more commands in flight, so the state grows to match."""
    env = make_env("small_loop", "state", overrides={"motor": {"delay": 0.3}})
    default = make_env("small_loop", "state")
    names = state_feature_names(env.task.config)
    assert len(names) > len(state_feature_names(default.task.config))
    assert env.reset().observation["state"].shape == (len(names),)


# ----- spawn ---------------------------------------------------------------------------------

def distance_to_footprint(obj, x: float, y: float) -> float:
    """Distance (m) from (x, y) to the object's footprint rectangle, 0 inside."""
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    u = c * (x - obj.x) + s * (y - obj.y)
    v = -s * (x - obj.x) + c * (y - obj.y)
    return math.hypot(max(abs(u) - obj.length / 2, 0.0), max(abs(v) - obj.width / 2, 0.0))


def spawn_clearances(env) -> list[float]:
    env.reset()
    x, y, _ = env.physics.pose()
    return [distance_to_footprint(obj, x, y) for obj in env.task.map.objects]


def test_spawn_keeps_clear_of_obstacles(make_env):
    """100 seeds on obstacle_loop: the axle point always starts >= 0.25 m from every obstacle
    footprint, with every check point on the road."""
    closest = []
    for seed in range(100):
        env = make_env("obstacle_loop", "state", seed=seed)
        closest.append(min(spawn_clearances(env)))
        dmap = env.task.map
        assert all(dmap.is_road(x, y) for x, y in env.physics.footprint_check_points())
    assert min(closest) >= 0.25


def test_spawn_clearance_is_what_keeps_obstacles_away(make_env):
    """Without the clearance rule some spawns land within 0.25 m of an obstacle (so the test
    above is not passing by luck)."""
    env = make_env("obstacle_loop", "state", seed=0,
                   overrides={"spawn": {"obstacle_clearance": 0.0}})
    closest = [min(spawn_clearances(env)) for _ in range(100)]
    assert min(closest) < 0.25


@pytest.mark.parametrize("action", ["continuous", "duty"])
def test_non_finite_action_is_refused_with_a_clear_error(action):
    """A NaN action never reaches the motor delay line: it raises ValueError naming it."""
    env = crllk.load("small_loop", observation="state", action=action, seed=0)
    env.reset()
    with pytest.raises(ValueError, match="not finite"):
        env.step(np.array([np.nan, 0.0]))


def test_constraints_are_declared_by_the_task():
    """Names of built-in constraints or full declarations; each adds a cost entry."""
    config = load_task_config("small_loop", {"constraints": [
        "lane", {"name": "weave", "signal": "lane_crossing", "aggregate": "mean",
                 "unit": "per step", "metric": "J_weave"}]})
    assert [c.name for c in config.constraints] == ["lane", "weave"]
    env = crllk.load("small_loop", observation="state", seed=0,
                     overrides={"constraints": ["lane", "collision", "crossing"]})
    assert {"cost_lane", "cost_collision", "cost_crossing"} <= set(env.reset().observation)


@pytest.mark.parametrize(("constraints", "problem"), [
    (["lane", "speed"], "constraints[1]: unknown constraint 'speed'"),
    ([], "constraints: expected a non-empty list"),
    (["lane", "lane"], "constraints[1]: 'lane' appears twice"),
    ([{"name": "x", "signal": "speed", "aggregate": "sum", "unit": "", "metric": "J"}],
     "constraints[0]: every key needs a non-empty string"),
    ([{"name": "x", "signal": "speed", "aggregate": "sum", "unit": "u", "metric": "J"}],
     "constraints[0].signal: unknown signal 'speed'"),
    ([{"name": "x", "signal": "collision", "aggregate": "max", "unit": "u", "metric": "J"}],
     "constraints[0].aggregate: must be one of mean, sum"),
    ([{"name": "x", "signal": "collision"}], "constraints[0]: missing keys"),
])
def test_bad_constraints_name_the_entry(constraints, problem):
    with pytest.raises(ConfigError, match=re.escape(problem)):
        load_task_config("small_loop", {"constraints": constraints})


@pytest.mark.parametrize(("before", "after", "crossed"), [
    (0.0, -0.10, 0.0),   # towards the yellow centre line (0.117 m left), not across
    (0.0, -0.13, 1.0),   # across it
    (-0.13, -0.16, 0.0),  # further into the other lane
    (-0.13, 0.0, 1.0),   # back across it
    (0.0, 0.13, 0.0),    # towards the white edge line (0.1365 m right), not across
    (0.10, 0.14, 1.0),   # across it
])
def test_lane_crossing_probes(before, after, crossed):
    """The crossing cost is 1 on a step whose start and end lie on either side of a lane
    line (lateral offsets in m from the lane centre, positive right)."""
    env = crllk.load("small_loop", observation="state", action="duty", seed=0,
                     overrides={"constraints": ["crossing"]})
    env.reset()
    task, physics = env.task, env.physics
    lane = next(ln for ln in task.map.lanes if ln.turn == 0)
    for lateral in (before, after):
        x, y, heading = lane.point_at(lane.length / 2, lateral)
        with physics.reset_context():
            physics.set_pose(x, y, heading)
        task.after_step(physics)
    assert task.get_observation(physics)["cost_crossing"] == crossed
