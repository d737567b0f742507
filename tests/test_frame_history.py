"""A policy's memory of recent camera images (``obs.history``): what it stacks, in which order,
from which steps, and that snapshots, resumed runs and exported pilots keep it exactly."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tiny_runs import assert_same_runs, compose_config, run_in_process

from crllk.config import validate
from crllk.envs.batched import make_env, merge_sim_states, split_sim_state
from crllk.errors import ConfigError
from crllk.tasks.frames import FrameHistory

HORIZON = {"horizon": 20}


def test_history_stacks_images_stride_steps_apart_newest_first():
    """Channels 3k..3k+2 hold the image of k * stride pushes ago; a restart fills every slot
    with the first image; other robots keep theirs."""
    history = FrameHistory(2, (1, 1, 3), count=3, stride=2)
    images = [np.full((2, 1, 1, 3), value, np.uint8) for value in range(10)]
    history.restart([0, 1], images[0])
    assert (history.stacked() == 0).all()
    for image in images[1:6]:
        history.push(image)
    stacked = history.stacked()
    assert stacked.shape == (2, 1, 1, 9)
    assert stacked[0, 0, 0].tolist() == [5] * 3 + [3] * 3 + [1] * 3
    history.restart([1], images[9][:1])
    assert history.stacked()[1, 0, 0].tolist() == [9] * 9
    assert history.stacked()[0, 0, 0].tolist() == [5] * 3 + [3] * 3 + [1] * 3


@pytest.mark.parametrize(("count", "stride"), [(0, 1), (2, 0)])
def test_history_rejects_empty_memories(count, stride):
    with pytest.raises(ValueError, match="at least 1"):
        FrameHistory(1, (30, 40, 3), count=count, stride=stride)


def drive(env, actions, tensordict):
    """Steps with automatic resets; returns each step's observation before it, its ``next``
    observation and done flags, and the carry."""
    seen = []
    for action in actions:
        before = tensordict["pixels"].clone()
        tensordict["action"] = action
        step, tensordict = env.step_and_maybe_reset(tensordict)
        seen.append((before, step["next", "pixels"].clone(), step["next", "done"].clone()))
    return seen, tensordict


def test_env_history_is_the_plain_env_s_past_images():
    """Against an env without history from the same seeds and actions: the newest image is
    the plain observation, older slots are the plain observations stride steps earlier within
    the same episode, and the episode's first image repeats back from its start (resets
    included)."""
    count, stride, steps = 3, 2, 30
    plain = make_env("small_loop", num_envs=2, seed=4, overrides=HORIZON)
    stacked = make_env("small_loop", num_envs=2, seed=4, overrides=HORIZON, history=count,
                       history_stride=stride)
    try:
        assert stacked.observation_spec["pixels"].shape == (2, 30, 40, 3 * count)
        actions = torch.randint(0, 3, (steps, 2), generator=torch.Generator().manual_seed(3))
        plain_seen, _ = drive(plain, actions, plain.reset())
        stacked_seen, _ = drive(stacked, actions, stacked.reset())
    finally:
        plain.close(), stacked.close()
    episodes: list[list[torch.Tensor]] = [[], []]  # each robot's images of its episode so far
    restarts = 0
    for (before, after, done), (stacked_before, stacked_after, _) in zip(
            plain_seen, stacked_seen, strict=True):
        for i in range(2):
            if not episodes[i]:
                episodes[i].append(before[i])
                assert torch.equal(stacked_before[i], before[i].repeat(1, 1, count))
            episodes[i].append(after[i])
            for k in range(count):
                expected = episodes[i][max(len(episodes[i]) - 1 - k * stride, 0)]
                assert torch.equal(stacked_after[i, ..., 3 * k:3 * k + 3], expected)
            if done[i]:
                episodes[i], restarts = [], restarts + 1
    assert restarts >= 2, "episodes restarted within the drive"


def test_snapshot_with_history_restores_exactly_and_splits():
    env = make_env("small_loop", num_envs=3, seed=1, history=2, history_stride=3,
                   overrides=HORIZON)
    restored = make_env("small_loop", num_envs=3, seed=9, history=2, history_stride=3,
                        overrides=HORIZON)
    other = make_env("small_loop", num_envs=3, seed=1, history=2, history_stride=1,
                     overrides=HORIZON)
    try:
        actions = torch.randint(0, 3, (25, 3), generator=torch.Generator().manual_seed(5))
        _, carry = drive(env, actions[:10], env.reset())
        snapshot = env.sim_state()
        expected, _ = drive(env, actions[10:], carry.clone())
        restored.reset()
        restored.load_sim_state(snapshot)
        got, _ = drive(restored, actions[10:], carry.clone())
        for (_, a, done_a), (_, b, done_b) in zip(got, expected, strict=True):
            assert torch.equal(a, b) and torch.equal(done_a, done_b)
        merged = merge_sim_states(split_sim_state(snapshot, [1, 2]))
        assert torch.equal(merged["history_images"], snapshot["history_images"])
        with pytest.raises(ValueError, match="history"):
            other.load_sim_state(snapshot)
    finally:
        env.close(), restored.close(), other.close()


def test_history_needs_pixels():
    with pytest.raises(ValueError, match="pixel"):
        make_env("small_loop", observation="state", history=2)
    with pytest.raises(ConfigError, match=r"obs\.history: needs obs=pixels"):
        validate(compose_config(["obs=state", "obs.history=2"]))


def test_run_with_history_resumes_exactly(tmp_path):
    """Two iterations then one more on resume equal three straight (the history of the
    running episodes is in the checkpoint)."""
    extra = ["obs=pixels", "obs.history=3", "obs.history_stride=2", "ppo.anneal_lr=false"]
    straight = run_in_process(tmp_path / "straight", 3, extra)
    run_in_process(tmp_path / "resumed", 2, extra)
    run_in_process(tmp_path / "resumed", 3, [*extra, "resume=true"])
    assert_same_runs(straight, tmp_path / "resumed", 3)
