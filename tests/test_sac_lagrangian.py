"""SAC-Lagrangian (:mod:`crllk.algos.sac_lagrangian`), the second learner: it trains through the
trainer's loop from state with discrete and continuous actions, learns from the penalised
reward of the multipliers of the moment, resumes exactly, and refuses what it cannot do in one
line."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict
from tiny_runs import assert_same_runs, read_rows, run_in_process

from crllk.algos.sac_lagrangian import PENALISED_REWARD, ReplayRing
from crllk.errors import ConfigError
from crllk.evaluation.runs import evaluate_run
from crllk.training.checkpoints import load_checkpoint

SAC = ["algo=sac_lagrangian", "obs=state", "eval.final=false", "algo.options.warmup_frames=32",
       "algo.options.batch_size=8", "algo.options.updates_per_frame=0.25"]
"""Tiny runs (``tiny_runs.TINY``: 16 frames per iteration): gradient steps from the third
iteration on, four per iteration."""


@pytest.mark.parametrize("action", ["discrete", "continuous"])
def test_it_trains_the_policy_through_the_trainer(tmp_path, action):
    run = run_in_process(tmp_path / action, 4, [*SAC, f"action={action}",
                                                 "algo.constraints.lane.threshold=0.01"])
    rows = read_rows(run / "metrics.csv")
    assert [float(r["buffer_frames"]) for r in rows] == [16, 32, 48, 64]
    assert [float(r["gradient_steps"]) for r in rows] == [0, 4, 4, 4]
    assert math.isnan(float(rows[0]["loss_qvalue"]))
    for row in rows[1:]:
        assert all(math.isfinite(float(row[k])) for k in
                   ("loss_actor", "loss_qvalue", "loss_alpha", "alpha", "entropy")), row
    assert not any(k.startswith("loss_objective") for k in rows[0])
    state = load_checkpoint(run / "checkpoints" / "last.pt")
    assert set(state) >= {"actor", "sac", "optimizer", "replay"}
    # the policy moved away from where a run of the same seed stands before its first step
    fresh = run_in_process(tmp_path / f"{action}-one", 1, [*SAC, f"action={action}"])
    before = load_checkpoint(fresh / "checkpoints" / "last.pt")["actor"]
    assert any(not torch.equal(before[k], state["actor"][k]) for k in before)
    # the kept policy evaluates like any other run's
    document = evaluate_run(run, episodes=2, seed=5, num_envs=2, name="eval-sac")
    assert (run / "eval-sac.json").is_file() and document["source"]["frames"] == 64


def test_the_penalised_reward_uses_the_multipliers_of_the_moment(tmp_path):
    """Worked numbers: r = 1, c_lane = 3, c_collision = 0.5 per step with λ = (2, 1) gives
    (1 − 2·3 − 1·0.5) / (1 + 2 + 1) = −1.375 as the reward the Q-targets read."""
    run = run_in_process(tmp_path / "run", 1, SAC)
    from crllk.training.build import build_run
    from crllk.training.runs import load_run_config

    env, learner, _, _ = build_run(load_run_config(run))
    env.close()
    learner.prepare(0, {"lane": 2.0, "collision": 1.0})
    sample = TensorDict({"next": {"reward": torch.ones(4, 1), "cost_lane": torch.full((4, 1), 3.0),
                                  "cost_collision": torch.full((4, 1), 0.5)}}, [4])
    out = learner.combination(sample)
    torch.testing.assert_close(out["next", PENALISED_REWARD], torch.full((4, 1), -1.375))
    torch.testing.assert_close(out["next", "reward"], torch.ones(4, 1))  # kept as stored


def test_a_stopped_run_resumes_exactly(tmp_path):
    """The replay buffer, the Q-networks and their targets, the temperature and the optimiser
    go into the checkpoint: two iterations, stopped, then two more equal four straight."""
    stopped = run_in_process(tmp_path / "stopped", 2, SAC)
    run_in_process(stopped, 4, [*SAC, "resume=true"])
    straight = run_in_process(tmp_path / "straight", 4, SAC)
    assert_same_runs(straight, stopped, 4)


def test_the_ring_overwrites_the_oldest_and_samples_what_it_holds():
    ring = ReplayRing(5)
    for start in (0, 3, 6):  # 9 transitions into 5 places: 4..8 remain
        ring.add(TensorDict({"x": torch.arange(start, start + 3.0)}, [3]))
    assert ring.size == 5 and ring.cursor == 4
    assert sorted(ring.storage["x"].tolist()) == [4.0, 5.0, 6.0, 7.0, 8.0]
    drawn = ring.sample(200, torch.Generator().manual_seed(0))["x"]
    assert set(drawn.tolist()) == {4.0, 5.0, 6.0, 7.0, 8.0}
    copy = ReplayRing(5)
    copy.load_state_dict(ring.state_dict())
    assert torch.equal(copy.storage["x"][:copy.size], ring.storage["x"][:ring.size])
    assert (copy.cursor, copy.size) == (ring.cursor, ring.size)


@pytest.mark.parametrize(("override", "message"), [
    ("obs=pixels", "override: obs: sac_lagrangian learns from state (obs=state): a replay "
                   "buffer of camera images would not fit a checkpoint"),
    ("algo.options.gamma=1.5", "override: algo.options.gamma: must lie in [0, 1], got 1.5"),
    ("algo.options.buffer_frames=16", "override: algo.options.buffer_frames: must hold "
                                      "warmup_frames (32) and batch_size (8), got 16"),
    ("model.policy_commands=true", "override: model.policy_commands: sac_lagrangian's policy "
                                   "reads the state alone; set model.policy_commands=false"),
    ("algo.options.gama=0.9", "override: algo.options.gama: no such setting (python -m "
                              "crllk.train --cfg job lists them all)"),
])
def test_what_it_cannot_do_is_one_line(tmp_path, override, message):
    with pytest.raises(ConfigError) as error:
        run_in_process(tmp_path / "run", 1, [*SAC, override])
    assert str(error.value) == message


def test_its_runs_have_a_folder_of_their_own():
    """The default run directory names the learner when it is not the paper's, so a SAC run
    never resumes (or refuses) a PPO run of the same task, action, observation and seed."""
    from crllk.config import validate
    from crllk.training.compose import compose_config

    sac = validate(compose_config(["algo=sac_lagrangian", "obs=state"])).default_run_dir()
    ppo = validate(compose_config(["obs=state"])).default_run_dir()
    assert sac.name == "crllk-sac_lagrangian-discrete-state-seed0"
    assert ppo.name == "crllk-discrete-state-seed0"


def test_a_buffer_smaller_than_one_iteration_is_refused(tmp_path):
    with pytest.raises(ConfigError) as error:
        run_in_process(tmp_path / "run", 1, [*SAC, "algo.options.buffer_frames=12",
                                             "algo.options.warmup_frames=8"])
    assert str(error.value) == ("override: algo.options.buffer_frames: must hold one "
                                "iteration's 16 frames (num_envs × rollout_steps), got 12")
