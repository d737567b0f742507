"""Collection from several worker processes (``workers``): the same run as with one process,
exact resume, and a clear refusal when num_envs does not split evenly.

A worker runs the policy on its share of the simulations, the one-process run on all of them
at once; on some CPUs the math libraries pick their matrix kernels by batch size, so the two
round the last bit of a policy output differently, and over a few PPO updates the runs drift
apart by rounding (on an Intel Xeon: 2e-9 in a policy output after two iterations; on an AMD
EPYC: not at all). Runs with different ``workers`` are therefore compared up to
:data:`tiny_runs.ROUNDING`; runs with the same ``workers`` (resume) bit for bit."""

from __future__ import annotations

import multiprocessing

import numpy as np
import pytest
from joblib import Parallel, delayed
from tiny_runs import assert_same_runs, read_rows, run_in_process

from crllk.config import validate
from crllk.envs.parallel import ParallelLaneKeepingEnv, WorkerError
from crllk.errors import ConfigError
from crllk.evaluation.runs import evaluate_run
from crllk.rl.rollout import run_episodes
from crllk.training.build import build_eval_env, worker_env
from crllk.training.compose import compose_config
from crllk.training.runs import load_actor, load_run_config

NUM_ENVS, ROLLOUT = 2, 4
SMALL = [f"num_envs={NUM_ENVS}", f"rollout_steps={ROLLOUT}", "obs=state", "eval.final=false",
         "ppo.anneal_lr=false"]
"""obs=state, two simulations, four steps per iteration; a constant learning rate, so that runs
of different lengths share their first iterations."""
FRAMES = NUM_ENVS * ROLLOUT


def test_two_workers_train_exactly_as_one_process(tmp_path):
    """workers=2 trains and writes metrics, and collects what one process would: the metrics
    and the final checkpoint (networks, multipliers, simulations, episode sums) equal those of
    workers=1 up to rounding."""
    two = run_in_process(tmp_path / "two", 3, [*SMALL, "workers=2"], frames_per_iteration=FRAMES)
    rows = read_rows(two / "metrics.csv")
    assert [int(r["iteration"]) for r in rows] == [1, 2, 3]
    assert int(rows[-1]["frames"]) == 3 * FRAMES
    one = run_in_process(tmp_path / "one", 3, SMALL, frames_per_iteration=FRAMES)
    assert_same_runs(one, two, 3, ignore=["workers"], close=True)


def test_two_workers_train_continuous_actions_exactly_as_one_process(tmp_path):
    """The tanh-Gaussian policy too: its samples are drawn in double precision from each
    simulation's stream, so the runs are equal up to the rounding of the policy's outputs."""
    continuous = [*SMALL, "action=continuous"]
    two = run_in_process(tmp_path / "two", 2, [*continuous, "workers=2"],
                         frames_per_iteration=FRAMES)
    one = run_in_process(tmp_path / "one", 2, continuous, frames_per_iteration=FRAMES)
    assert_same_runs(one, two, 2, ignore=["workers"], close=True)


def test_two_workers_stopped_run_resumes_exactly(tmp_path):
    """A workers=2 run stopped after two iterations (its last checkpoint) and resumed with two
    workers for two more equals an uninterrupted workers=2 run bit for bit. The simulations'
    snapshot goes through the workers both ways."""
    stopped = run_in_process(tmp_path / "stopped", 2, [*SMALL, "workers=2"],
                             frames_per_iteration=FRAMES)
    run_in_process(stopped, 4, [*SMALL, "workers=2", "resume=true"], frames_per_iteration=FRAMES)
    straight = run_in_process(tmp_path / "straight", 4, [*SMALL, "workers=2"],
                              frames_per_iteration=FRAMES)
    assert_same_runs(straight, stopped, 4)


def test_workers_that_do_not_divide_num_envs_are_refused(tmp_path):
    """workers=3 with num_envs=2: one line naming the setting, before any process starts."""
    with pytest.raises(ConfigError) as error:
        run_in_process(tmp_path / "run", 1, [*SMALL, "workers=3"], frames_per_iteration=FRAMES)
    message = str(error.value)
    assert message == ("override: workers: must divide num_envs (2) into equal shares, "
                       "got 3 (obs=pixels and obs=state set 2; workers=1 steps them in this "
                       "process, without collect_ahead)"), message
    assert not (tmp_path / "run").exists()


def test_two_workers_train_from_pixels_exactly_as_one_process(tmp_path):
    """The default path from the camera (obs=pixels puts the simulations in two worker
    processes): a workers=2 run equals the one-process run, metrics, checkpoint and the
    final evaluation (reseeded and played in the workers too), up to rounding (the workers
    render the same images as the main process would)."""
    pixels = [f"num_envs={NUM_ENVS}", f"rollout_steps={ROLLOUT}", "obs=pixels",
              "ppo.anneal_lr=false", "threads=1"]
    two = run_in_process(tmp_path / "two", 2, [*pixels, "workers=2"], frames_per_iteration=FRAMES)
    one = run_in_process(tmp_path / "one", 2, [*pixels, "workers=1"], frames_per_iteration=FRAMES)
    assert_same_runs(one, two, 2, ignore=["workers"], close=True)
    evaluations = [read_rows(run / "eval.csv") for run in (one, two)]
    assert len(evaluations[0]) == 1
    for row in evaluations:
        row[0].pop("evaluation_s")
        row[0].pop("time_s")
    assert evaluations[0] == evaluations[1]


def test_evaluation_in_two_workers_plays_the_same_episodes(tmp_path):
    """A run's evaluation env follows its workers (build_eval_env): the same episodes, their
    start directions, ends and actions as in one process, from the same spawn seed."""
    run = run_in_process(tmp_path / "run", 1, ["obs=pixels", "eval.final=false", "threads=1"])
    config = load_run_config(run)
    results, kinds = [], []
    for workers in (1, 2):
        config.workers = workers
        env = build_eval_env(config, num_envs=2, seed=5)
        kinds.append(type(env).__name__)
        try:
            actor, _ = load_actor(run, env)
            results.append(run_episodes(env, actor, 4, deterministic=False, sample_seed=5))
        finally:
            env.close()
    assert kinds == ["BatchedLaneKeepingEnv", "ParallelLaneKeepingEnv"]
    one, two = results
    assert one.episodes == two.episodes
    assert one.directions == two.directions and None not in one.directions
    assert one.hit_objects == two.hit_objects and one.terminations == two.terminations
    assert one.hit_movers == two.hit_movers == [None] * 4
    assert one.lateral_deviations == two.lateral_deviations  # the lane pose crosses too
    assert one.outside_lane_steps == two.outside_lane_steps
    assert None not in one.lateral_deviations
    for a, b in zip(one.actions, two.actions, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_failing_worker_is_one_line_naming_it():
    """A worker whose env cannot be built: the parent raises one line naming the worker and
    the error, keeps the worker's traceback in the exception's notes, and stops the others."""
    config = validate(compose_config(["obs=state", "num_envs=2"]))
    shares = [{"config": config, "first": 0, "count": 1}, {"config": config, "first": 1,
                                                           "count": 0}]
    with pytest.raises(WorkerError) as error:
        ParallelLaneKeepingEnv(worker_env, shares)
    assert str(error.value) == ("simulation worker 1 failed: ValueError: num_envs must be at "
                                "least 1, got 0")
    assert "Traceback" in error.value.__notes__[0]
    assert not multiprocessing.active_children()


def test_workers_start_inside_joblib_workers(tmp_path):
    """Experiments evaluate runs in joblib (loky) worker processes, whose global start method
    is loky's: a run trained with workers=2 still evaluates there in two worker processes of
    its own, with the same episodes as in this process."""
    run = run_in_process(tmp_path / "run", 1, [*SMALL, "workers=2"], frames_per_iteration=FRAMES)
    here = evaluate_run(run, episodes=2, num_envs=2, name="here")
    there = Parallel(n_jobs=2)(delayed(evaluate_run)(run, episodes=2, num_envs=2, name=name)
                               for name in ("pool0", "pool1"))
    for document in there:
        assert document["episodes"] == here["episodes"]
