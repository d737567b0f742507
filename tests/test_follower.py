"""The scripted lane follower: the end-to-end check of geometry, physics and task."""

from __future__ import annotations

import math

import numpy as np
import pytest

import crllk
from crllk.tasks.follower import LaneFollower


def _drive(env, follower, max_steps=None):
    timestep, steps = env.step(np.zeros(2)), 1
    distance, lane_costs, collisions = timestep.reward, [], 0.0
    while not timestep.last():
        timestep = env.step(follower.duty(env.physics))
        steps += 1
        distance += timestep.reward
        lane_costs.append(float(timestep.observation["cost_lane"]))
        collisions += float(timestep.observation["cost_collision"])
    return timestep, steps, distance, float(np.mean(lane_costs)), collisions


@pytest.mark.parametrize(("task", "horizon"), [("small_loop", 900), ("zigzag", 2400)])
@pytest.mark.parametrize("seed", [0, 1])
def test_follower_completes_a_lap_cleanly(task, horizon, seed):
    """Whichever direction it spawns in, the follower drives at least one full lap with mean
    lane cost < 0.3 dm and no collision."""
    env = crllk.load(task, observation="state", action="duty", seed=seed,
                     overrides={"horizon": horizon})
    env.reset()
    follower = LaneFollower(env.task.map, env.task.config.motor)
    timestep, steps, distance, lane_cost, collisions = _drive(env, follower)
    lap = max(env.task.map.lap_length("intended"), env.task.map.lap_length("reverse"))
    assert env.task.outcome.termination is None
    assert steps == horizon and timestep.discount == 1.0
    assert distance >= lap
    assert lane_cost < 0.3
    assert collisions == 0


def test_follower_hits_the_in_lane_duckie_on_obstacle_loop():
    """Driving west along the top row, the follower runs into the duckie at pos [3.5, 1.2]; the
    episode ends there with c_coll = 1 on the last step."""
    env = crllk.load("obstacle_loop", observation="state", action="duty", seed=0)
    env.reset()
    s = env.task.map.tile_size
    rows = env.task.map.rows
    lane_y = (rows - 1 - 1 + 0.5) * s + 0.117  # west-bound lane of row 1
    env.physics.set_pose(5.5 * s, lane_y, math.pi)
    env.physics.forward()
    follower = LaneFollower(env.task.map, env.task.config.motor)
    timestep, *_ = _drive(env, follower)
    assert env.task.outcome.termination == "collision"
    assert timestep.discount == 0.0
    assert timestep.observation["cost_collision"] == 1.0
    x, y, _ = env.physics.pose()
    duckie = env.task.map.objects[0]
    assert duckie.kind == "duckie"
    assert math.hypot(x - duckie.x, y - duckie.y) < 0.2
