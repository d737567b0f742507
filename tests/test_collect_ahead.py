"""``collect_ahead``: the workers collect the next batch during the update, with the policy
as it was before it; a stopped run resumes exactly, with any number of workers, and the
setting is refused with remote collectors."""

from __future__ import annotations

import copy

import pytest
import torch
from tiny_runs import assert_same_runs, read_rows, run_in_process

from crllk.config import validate
from crllk.errors import ConfigError
from crllk.training.batches import BatchSource, collect_batch
from crllk.training.build import build_run
from crllk.training.checkpoints import load_checkpoint
from crllk.training.compose import compose_config

NUM_ENVS, ROLLOUT = 2, 4
FRAMES = NUM_ENVS * ROLLOUT
AHEAD = [f"num_envs={NUM_ENVS}", f"rollout_steps={ROLLOUT}", "obs=state", "eval.final=false",
         "ppo.anneal_lr=false", "workers=2", "collect_ahead=true"]


def test_a_batch_collected_ahead_is_collected_by_the_policy_before_the_update():
    """prefetch() copies the policy: changing the networks afterwards (as the update does)
    leaves the batch under way as the unchanged policy collects it from the same simulations
    and streams; collecting with the changed policy gives another batch. Meanwhile the workers
    refuse any other command."""
    config = validate(compose_config(AHEAD))
    env, learner, _, _ = build_run(config)
    try:
        carry = env.reset()
        snapshot, streams = env.sim_state(), learner.action_noise.states()
        before = copy.deepcopy(learner.actor)
        source = BatchSource(env, learner.actor, ROLLOUT, learner.action_noise, carry.clone(),
                             collect_ahead=True)
        source.prefetch()
        for busy in (env.reset, env.sim_state):
            with pytest.raises(RuntimeError, match="finish"):
                busy()
        with torch.no_grad():
            for parameter in learner.actor.parameters():
                parameter.add_(0.5)
        ahead = source.next()
        assert source.pending() is None and not env.running
        with pytest.raises(RuntimeError, match="no run was started"):
            env.finish()

        def collected_by(actor):
            env.load_sim_state(snapshot)
            learner.action_noise.load_states(streams)
            return collect_batch(env, actor, carry.clone(), ROLLOUT, learner.action_noise)[0]

        expected = collected_by(before)
        for key in ("action", "action_log_prob", "logits", ("next", "reward")):
            torch.testing.assert_close(ahead[key], expected[key], rtol=0, atol=0)
        changed = collected_by(learner.actor)
        assert not torch.equal(changed["logits"], ahead["logits"])
    finally:
        env.close()


def test_a_run_collecting_ahead_keeps_its_next_batch_and_resumes_exactly(tmp_path):
    """A collect_ahead run stopped after two iterations keeps the batch it collected during
    the second update in its checkpoint, and resumed for two more equals an uninterrupted run
    bit for bit: one that checkpoints only at its end, so its batches come straight from
    the collections under way, and across the teacher's end (after two iterations), where
    the workers' teacher flag turns off between a collection and the next."""
    teacher = ["teacher.final=0", f"teacher.frames={2 * FRAMES}"]
    stopped = run_in_process(tmp_path / "stopped", 2, [*AHEAD, *teacher],
                             frames_per_iteration=FRAMES)
    ahead = load_checkpoint(stopped / "checkpoints" / "last.pt")["ahead"]
    assert ahead is not None and ahead["batch_size"] == [NUM_ENVS, ROLLOUT]
    run_in_process(stopped, 4, [*AHEAD, *teacher, "resume=true"], frames_per_iteration=FRAMES)
    straight = run_in_process(tmp_path / "straight", 4, [*AHEAD, *teacher, "checkpoint_every=4"],
                              frames_per_iteration=FRAMES)
    assert_same_runs(straight, stopped, 4, ignore=["checkpoint_every"])
    rows = read_rows(straight / "metrics.csv")
    assert [float(r["loss_imitation"]) != 0 for r in rows] == [True, True, False, False]


def test_collecting_ahead_learns_from_older_batches(tmp_path):
    """The first batch is the same either way (the initial policy collects it); the second
    is collected by the policy before the first update instead of after it, so the runs part
    from there (collect_ahead changes what is learned)."""
    ahead = run_in_process(tmp_path / "ahead", 2, AHEAD, frames_per_iteration=FRAMES)
    straight = run_in_process(tmp_path / "straight", 2, [*AHEAD, "collect_ahead=false"],
                              frames_per_iteration=FRAMES)
    rows = [read_rows(run / "metrics.csv") for run in (ahead, straight)]
    assert rows[0][0]["loss_objective"] == rows[1][0]["loss_objective"]
    assert rows[0][1]["loss_objective"] != rows[1][1]["loss_objective"]


def test_collecting_ahead_with_remote_collectors_is_refused():
    """One line naming the setting: remote collectors cannot collect during the update."""
    with pytest.raises(ConfigError) as error:
        validate(compose_config(["obs=state", "collect_ahead=true", "collector=ray",
                                 "workers=2"]))
    assert "collect_ahead: needs the simulations in worker processes" in str(error.value)


def test_one_worker_collecting_ahead_learns_what_two_do(tmp_path):
    """With workers=1 the simulations go to one worker process, which collects during the
    update as two do: the same run bit for bit (each simulation samples from its own stream),
    also when it is stopped and resumed with two."""
    one = run_in_process(tmp_path / "one", 2, [*AHEAD, "workers=1"], frames_per_iteration=FRAMES)
    run_in_process(one, 3, [*AHEAD, "resume=true"], frames_per_iteration=FRAMES)
    two = run_in_process(tmp_path / "two", 3, AHEAD, frames_per_iteration=FRAMES)
    assert_same_runs(two, one, 3, ignore=["workers"])


@pytest.mark.parametrize(("overrides", "labels"), [
    ([], ["state", "state, collect_ahead", "pixels"]),
    (["workers=1"], ["state", "state, collect_ahead", "pixels"]),
    (["collect_ahead=true"], ["state, collect_ahead", "pixels, collect_ahead"])])
def test_the_bench_times_state_collecting_ahead_where_it_can(overrides, labels):
    """``python -m crllk.bench --training`` adds the state figure collecting ahead, unless the
    overrides decide collect_ahead themselves."""
    from crllk.bench.cli import training_bench_configs

    configs = training_bench_configs("small_loop", overrides)
    assert [c.obs.name + (", collect_ahead" if c.collect_ahead else "") for c in configs] == labels


def test_the_collect_ahead_trial_rows_are_their_validation_evaluations():
    """The Scaling out page's trial: each run's 400 validation episodes, sampled and deployed,
    the sequential and the collecting-ahead run of each map and seed, every one within both
    thresholds (without a collision on the maps without obstacles); the prose's largest
    difference between the loops."""
    import json
    from pathlib import Path

    from docs_pages import page

    runs = Path(__file__).resolve().parents[1] / "results/runs/state"
    text = page("scaling-out.md")
    largest = (0.0, "")

    def cell(document: dict) -> str:
        summary, episodes = document["summary"], document["episodes"]
        hits = int(sum(e["cost_collision"] for e in episodes))
        assert len(episodes) == 400 and document["evaluation"]["seed"] == 1_000_000
        return (f"{summary['J_clane']:.3f} / {summary['J_coll']:.4f} ({hits} of 400) / "
                f"{summary['J_R']:.2f}")

    for task in ("small_loop", "zigzag", "obstacle_loop"):
        for seed in (0, 1):
            found = {}
            for arm, label in (("CRLLK-D", "sequential"), ("CRLLK-D-ahead", "collecting ahead")):
                run = runs / task / f"{arm}-a0.5-seed{seed}"
                documents = [json.loads((run / f"{name}.json").read_text())
                             for name in ("val400", "val400-deployed")]
                assert documents[1]["evaluation"]["deployed"] == "expected_duty"
                assert f"| `{task}`, seed {seed}, {label} | {cell(documents[0])} | " \
                       f"{cell(documents[1])} |" in text
                found[arm] = [d["summary"]["J_clane"] for d in documents]
                assert max(found[arm]) < 0.5
                most = 0.02 if task == "obstacle_loop" else 0.0  # the only map with obstacles
                assert all(d["summary"]["J_coll"] <= most for d in documents)
            assert ("collect_ahead: true" in (runs / task / f"CRLLK-D-ahead-a0.5-seed{seed}"
                                               / "config.yaml").read_text())
            for which in (0, 1):
                gap = abs(found["CRLLK-D"][which] - found["CRLLK-D-ahead"][which])
                if gap > largest[0]:
                    largest = (gap, f"`{task}` seed {seed}'s "
                               f"{'deployed' if which else 'sampled'} policy (J_clane "
                               f"{found['CRLLK-D-ahead'][which]:.3f} dm collecting ahead, against "
                               f"{found['CRLLK-D'][which]:.3f})")
    prose = " ".join(text.split())
    assert ("The largest difference in J_clane between sequential and ahead is "
            + largest[1]) in prose
    hits = {}
    for arm in ("CRLLK-D", "CRLLK-D-ahead"):
        for seed in (0, 1):
            run = runs / "obstacle_loop" / f"{arm}-a0.5-seed{seed}"
            for name in ("val400", "val400-deployed"):
                episodes = json.loads((run / f"{name}.json").read_text())["episodes"]
                assert all(e["direction"] == "intended" for e in episodes if e["cost_collision"])
                hits[arm, seed, name] = int(sum(e["cost_collision"] for e in episodes))
    deployed = {hits[arm, seed, "val400-deployed"] for arm in ("CRLLK-D", "CRLLK-D-ahead")
                for seed in (0, 1)}
    assert len(deployed) == 1 and f"collide equally ({deployed.pop()} of 400 on each seed)" in prose
    assert (f"(seed 0: {hits['CRLLK-D-ahead', 0, 'val400']} of 400 collecting ahead, against "
            f"{hits['CRLLK-D', 0, 'val400']}, J_coll {hits['CRLLK-D-ahead', 0, 'val400'] / 400:.3f}"
            f" against {hits['CRLLK-D', 0, 'val400'] / 400:.3f}, both within α2)") in prose
    assert hits["CRLLK-D", 1, "val400"] == hits["CRLLK-D-ahead", 1, "val400"]
