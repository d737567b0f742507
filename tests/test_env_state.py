"""Snapshots of the batched environment: ``load_sim_state(sim_state())`` into a fresh env makes
it step bit-identically to the original, through automatic partial resets and a file."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDictBase

from crllk.envs.batched import BatchedLaneKeepingEnv, make_env

TASK = "small_loop"
HORIZON = {"horizon": 30}
"""Short episodes, so time-limit resets happen before and after the snapshot."""
OUTPUT_KEYS = ("reward", "cost_lane", "cost_collision", "terminated", "truncated", "done")


@pytest.fixture
def build():
    """Build environments and close them (releasing GL contexts) after the test."""
    built: list[BatchedLaneKeepingEnv] = []

    def make(observation: str = "state", action: str = "discrete", num_envs: int = 3,
             seed: int = 0) -> BatchedLaneKeepingEnv:
        env = make_env(TASK, num_envs=num_envs, observation=observation, action=action,
                       seed=seed, overrides=HORIZON)
        built.append(env)
        return env

    yield make
    for env in built:
        env.close()


def random_actions(env: BatchedLaneKeepingEnv, steps: int, generator: torch.Generator):
    """``[steps, N, ...]`` actions within the env's action spec."""
    n = env.num_envs
    if env.action_type == "discrete":
        return torch.randint(0, 3, (steps, n), generator=generator)
    return torch.rand((steps, n, 2), generator=generator) * 2 - 1


def drive(env: BatchedLaneKeepingEnv, actions: torch.Tensor,
          tensordict: TensorDictBase) -> tuple[TensorDictBase, TensorDictBase]:
    """Step through ``actions`` with automatic partial resets: the stacked transitions
    ``[N, T]`` and the tensordict to carry on from."""
    steps = []
    for action in actions:
        tensordict["action"] = action
        step, tensordict = env.step_and_maybe_reset(tensordict)
        steps.append(step)
    return torch.stack(steps, dim=1), tensordict


def assert_identical(got: TensorDictBase, expected: TensorDictBase, observation: str) -> None:
    for key in (*OUTPUT_KEYS, observation):
        assert torch.equal(got["next", key], expected["next", key]), key
    assert torch.equal(got[observation], expected[observation])


@pytest.mark.parametrize(("observation", "action", "num_envs", "before", "after"),
                         [("state", "discrete", 3, 40, 60),
                          ("state", "continuous", 3, 40, 40),
                          ("pixels", "discrete", 2, 32, 30)])
def test_restored_env_steps_identically(build, tmp_path, observation, action, num_envs,
                                        before, after):
    """Env B restored from env A's snapshot (directly, and through ``torch.save`` and
    ``torch.load``) replays A's next steps bit for bit, resets included."""
    original = build(observation, action, num_envs)
    generator = torch.Generator().manual_seed(11)
    _, carried = drive(original, random_actions(original, before, generator), original.reset())
    assert original.step_counts.max() < before, "a reset happened before the snapshot"
    snapshot = original.sim_state()
    torch.save(snapshot, tmp_path / "env.pt")
    tail = random_actions(original, after, generator)
    expected, _ = drive(original, tail, carried.clone())
    assert expected["next", "done"].any(), "a reset happens after the snapshot"

    for restored_state in (snapshot, torch.load(tmp_path / "env.pt")):
        restored = build(observation, action, num_envs, seed=123)
        restored.reset()
        restored.load_sim_state(restored_state)
        assert restored.seeds == original.seeds
        got, _ = drive(restored, tail, carried.clone())
        assert_identical(got, expected, observation)


def test_snapshot_is_not_shared(build):
    """Stepping on after a snapshot does not change it."""
    env = build()
    env.rollout(5)
    snapshot = env.sim_state()
    observations = snapshot["observations"].clone()
    env.rollout(3)
    assert torch.equal(snapshot["observations"], observations)
    assert snapshot["step_counts"] == [5, 5, 5]


@pytest.mark.parametrize(("change", "value"),
                         [("num_envs", 2), ("observation", "pixels"), ("action", "continuous")])
def test_mismatched_snapshot_is_rejected(build, change, value):
    """A snapshot only loads into an env built with the same arguments."""
    arguments = {"observation": "state", "action": "discrete", "num_envs": 3}
    snapshot = build(**arguments).sim_state()
    other = build(**{**arguments, change: value})
    with pytest.raises(ValueError, match=change):
        other.load_sim_state(snapshot)


def test_snapshot_of_another_task_is_rejected(build):
    env = build()
    snapshot = {**env.sim_state(), "task": "zigzag"}
    with pytest.raises(ValueError, match="task"):
        env.load_sim_state(snapshot)
