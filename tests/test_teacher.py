"""The privileged teacher: the swerving follower's duties as actions of each action type, the
teacher's driving, and the ``teacher_action`` key of the batched env."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

import crllk
from crllk.rl.rollout import run_episodes
from crllk.tasks.actions import (
    action_duty,
    drive_turn_duty,
    duty_to_action,
    velocity_steering_duty,
)
from crllk.tasks.teacher import Teacher


@pytest.mark.parametrize(("duty", "expected"), [
    ((0.04, 0.4), 0),    # the left turn itself
    ((0.25, 0.44), 0),   # difference 0.19 > 0.18: nearer the left turn
    ((0.3, 0.3), 2),
    ((0.3, 0.45), 2),    # difference 0.15: nearer straight
    ((0.5, 0.1), 1),
])
def test_discrete_teacher_takes_the_nearest_turn(duty, expected):
    assert duty_to_action("discrete", np.array(duty)).item() == expected


@pytest.mark.parametrize("action", [(0.0, 0.0), (-0.6, 0.3), (0.9, -1.0)])
def test_continuous_teacher_inverts_the_mappings(action):
    """duty_to_action undoes drive_turn_duty and the Duckietown inverse kinematics."""
    np.testing.assert_allclose(
        duty_to_action("continuous", np.array(drive_turn_duty(*action))), action, atol=1e-12)
    small = (0.5 * action[0], 0.5 * action[1])  # inside the unsaturated range of the IK
    np.testing.assert_allclose(
        duty_to_action("duckietown", np.array(velocity_steering_duty(*small))), small,
        atol=1e-12)
    assert np.all(np.abs(duty_to_action("continuous", np.array([1.0, -1.0]))) <= 1.0)


@pytest.mark.parametrize("action", [(0.0, 0.0), (-1.0, 0.3), (0.9, -1.0)])
def test_the_stoppable_teacher_inverts_its_mapping(action):
    """duty_to_action undoes the stoppable mapping, whose velocity -1 is a mean duty of 0 and
    +1 the continuous one's largest."""
    duty = drive_turn_duty(*action, least=0.0)
    np.testing.assert_allclose(duty_to_action("stoppable", np.array(duty)), action, atol=1e-12)
    assert action_duty("stoppable", (-1.0, 0.0)) == (0.0, 0.0)
    assert action_duty("stoppable", (1.0, 0.2)) == action_duty("continuous", (1.0, 0.2))
    assert action_duty("continuous", (0.3, -0.5)) == drive_turn_duty(0.3, -0.5)


@pytest.mark.parametrize("action", ["discrete", "continuous"])
def test_teacher_passes_the_obstacles(action):
    """Driving its own actions from 20 encounter starts on obstacle_loop (horizon 150), the
    teacher never collides nor leaves the road."""
    env = crllk.make_env("obstacle_loop", num_envs=10, observation="state", action=action,
                         seed=4, overrides={"horizon": 150, "spawn": {"encounters": 1.0}})
    teachers = [Teacher(env.config, task.obstacles, action) for task in env.tasks]
    dtype = torch.int64 if action == "discrete" else torch.float32

    def policy(td):
        actions = np.stack([t.action(p) for t, p in zip(teachers, env.physics, strict=True)])
        return td.set("action", torch.as_tensor(actions, dtype=dtype))

    result = run_episodes(env, policy, 20)
    assert result.summary.J["J_coll"] == 0.0
    assert result.summary.J_R > 0.3


def test_teacher_action_key_in_the_batched_env():
    """With teacher=True observations carry the teacher's action of the observed state, equal
    to asking a teacher directly; the specs hold, and switched off it writes zeros: no action
    left over from before (a resumed run sees what the straight one does)."""
    env = crllk.make_env("obstacle_loop", num_envs=3, observation="state", action="discrete",
                         seed=0, teacher=True)
    check_env_specs(env, seed=0)
    td = env.reset()
    teachers = [Teacher(env.config, task.obstacles, "discrete") for task in env.tasks]
    direct = [t.action(p).item() for t, p in zip(teachers, env.physics, strict=True)]
    assert td["teacher_action"].tolist() == direct
    env.teacher_active = False
    assert any(direct)  # what is left over would not be zeros
    off = env.rand_step(td)["next", "teacher_action"]
    assert off.tolist() == [0, 0, 0]
    assert "teacher_action" not in crllk.make_env("small_loop", observation="state").reset()


def test_the_teacher_is_evaluated_in_a_policy_action_type():
    """``crllk.evaluate teacher=true action=discrete``: the teacher answers in the three turns
    (the imitation target of a discrete policy), through the same metrics."""
    from crllk.evaluation.runs import evaluate_follower

    document = evaluate_follower("obstacle_loop", episodes=2, num_envs=2, avoid_obstacles=True,
                                 action="discrete")
    assert document["source"]["action"] == "discrete"
    assert set(document["action_histogram"]) == {"left", "right", "straight"}
    assert sum(document["action_histogram"].values()) == pytest.approx(1.0)  # shares
    assert all(sum(e["actions"].values()) == e["length"] for e in document["episodes"])


def test_the_evaluated_teacher_keeps_the_margin_asked_for():
    """``crllk.evaluate teacher=true margin=0.07``: the teacher evaluated is the one a run with
    ``teacher.margin=0.07`` imitates, and the document says which."""
    from crllk.evaluation.runs import evaluate_follower
    from crllk.tasks.follower import FollowerPolicy

    env = crllk.make_env("obstacle_loop", num_envs=1, observation="state", seed=0)
    try:
        policy = FollowerPolicy(env, avoid_obstacles=True, margin=0.07)
        assert policy.follower.gains.avoid_margin == 0.07
    finally:
        env.close()
    document = evaluate_follower("obstacle_loop", episodes=1, num_envs=1, avoid_obstacles=True,
                                 margin=0.07)
    assert document["evaluation"]["margin"] == 0.07


def test_the_teachers_margin_is_a_training_setting():
    """``teacher.margin`` sets the gap the teacher keeps beside obstacles; a wider one swerves
    further left in front of the same obstacle."""
    from crllk.config import validate
    from crllk.training.build import build_env
    from crllk.training.compose import compose_config

    config = validate(compose_config(["task=obstacle_loop", "obs=state", "teacher.margin=0.07"]))
    env = build_env(config, num_envs=1, seed=0, training=True)
    try:
        assert env.teachers[0].follower.gains.avoid_margin == 0.07
        narrow, wide = (Teacher(env.config, env.tasks[0].obstacles, "duty", margin)
                        for margin in (0.04, 0.07))
        lane, obstacle = env.tasks[0]._blocking[0]
        pose = env.config.map.lane_pose(*lane.point_at(obstacle.along_start - 0.3, 0.0))
        assert wide.follower.swerve_target(pose) < narrow.follower.swerve_target(pose) < 0
    finally:
        env.close()
