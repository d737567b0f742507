"""The Gymnasium adapter: every registered id passes Gymnasium's own checker, costs travel in
``info``, seeds fix the spawns, Safety-Gymnasium's step, and a library trains through it."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import crllk.gym
from crllk.gym import ENVIRONMENT_IDS, SafetyStep, environment_id
from crllk.paths import task_names

REPO = Path(__file__).resolve().parent.parent


def test_ids_cover_every_task_and_variant():
    assert environment_id("obstacle_loop") == "crllk/ObstacleLoop-v0"
    assert len(ENVIRONMENT_IDS) == len(task_names()) * 4
    assert "crllk/TrafficLoop-v0" in ENVIRONMENT_IDS
    assert {"crllk/SmallLoop-v0", "crllk/Zigzag-State-v0", "crllk/ObstacleLoop-Continuous-v0",
            "crllk/SmallLoop-StateContinuous-v0"} <= set(ENVIRONMENT_IDS)


@pytest.mark.parametrize("env_id", ENVIRONMENT_IDS)
def test_gymnasium_checker_passes(env_id):
    env = gymnasium.make(env_id, render_mode="rgb_array")
    check_env(env.unwrapped, skip_render_check=False)
    env.close()


def test_costs_are_in_info_and_a_seed_fixes_the_spawn():
    env = crllk.gym.make_env("obstacle_loop", observation="state")
    first, _ = env.reset(seed=5)
    again, _ = env.reset(seed=5)
    other, _ = env.reset(seed=6)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    env.reset(seed=5)
    done, steps, total = False, 0, {"cost_lane": 0.0, "cost_collision": 0.0}
    while not done:
        _, _, terminated, truncated, info = env.step(2)  # straight on, off at a curve
        steps += 1
        assert info["cost"] == pytest.approx(info["cost_lane"] + info["cost_collision"])
        total = {k: total[k] + info[k] for k in total}
        done = terminated or truncated
    assert terminated and info["termination"] in ("off_road", "collision")
    assert total["cost_lane"] > 0 and steps < 512


def test_safety_gymnasium_step():
    env = SafetyStep(crllk.gym.make_env("small_loop", observation="state"))
    env.reset(seed=0)
    observation, reward, cost, terminated, truncated, info = env.step(2)
    assert cost == info["cost"] and observation.shape == env.observation_space.shape
    assert isinstance(reward, float) and not terminated and not truncated


def test_stable_baselines3_trains_through_the_adapter(monkeypatch, capsys):
    """The example in examples/ at a tiny budget: PPO of Stable-Baselines3 learns for 256
    steps, then drives one episode; its return and costs are printed."""
    monkeypatch.setattr(sys, "argv", ["example", "--steps", "256", "--episodes", "1"])
    runpy.run_path(str(REPO / "examples" / "stable_baselines3_ppo.py"), run_name="__main__")
    printed = capsys.readouterr().out
    assert "'return'" in printed and "'cost_lane'" in printed and "'cost'" in printed


@pytest.mark.parametrize("action", [1.7, 3, -1, "1", [1], np.float32(1.0)])
def test_a_discrete_action_that_is_not_one_is_refused(action):
    env = gymnasium.make("crllk/SmallLoop-State-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action: expected a whole number from 0 to 2"):
        env.step(action)
    env.step(np.int64(1))  # numpy's whole numbers are actions
    env.close()


@pytest.mark.parametrize("action", [[0.1], [np.nan, 0.0], [0.0, np.inf]])
def test_a_continuous_action_must_be_two_finite_numbers(action):
    env = gymnasium.make("crllk/SmallLoop-StateContinuous-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action: expected 2 finite numbers"):
        env.step(action)
    env.step(np.zeros(2))
    env.close()
