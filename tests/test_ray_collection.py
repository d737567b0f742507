"""Collection by remote collectors on a Ray cluster (``collector=ray``): the batch keeps the local
layout, the collectors act with the weights sent to them, a tiny run trains through a Ray head
on 127.0.0.1 and resumes from its checkpoint with fresh episodes on a private Ray instance,
nothing listens beyond 127.0.0.1, and bad settings are one line.

The Ray tests are slow (``pytest -m slow -k ray``) and need the cluster extra."""

from __future__ import annotations

import copy
import importlib.util
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import ray_cluster
import torch
from tensordict import TensorDict
from tiny_runs import FRAMES_PER_ITERATION, NUM_ENVS, ROLLOUT, TINY, read_rows, run_in_process
from torchrl.envs.utils import ExplorationType

from crllk.envs.distributed import merge_batches
from crllk.envs.remote import LaneKeepingCollector
from crllk.errors import ConfigError
from crllk.rl.rollout import collect
from crllk.train import resolve_config
from crllk.training.build import build_run, worker_env
from crllk.training.checkpoints import load_checkpoint
from crllk.training.compose import compose_config

REPO = Path(__file__).resolve().parents[1]
STATE = ["obs=state", "eval.final=false"]
RAY_RUN_S = 600
"""The longest a tiny run through Ray may take on a loaded machine (s)."""


@pytest.mark.parametrize(("overrides", "message"), [
    (["collector=ray", "workers=3"],
     "override: workers: must divide num_envs (2) into equal shares, got 3 (obs=pixels and "
     "obs=state set 2; workers=1 steps them in this process, without collect_ahead)"),
    (["ray_address=127.0.0.1:6379"],
     "override: ray_address: is only used with collector=ray, got collector=local"),
    (["collector=ray", "ray_address=head"],
     "override: ray_address: must be host:port with a port in [1, 65535], got 'head'"),
    (["collector=ray", "ray_address=127.0.0.1:0"],
     "override: ray_address: must be host:port with a port in [1, 65535], got '127.0.0.1:0'"),
    (["collector=slurm"], "override: collector: must be one of local, ray, got 'slurm'"),
])
def test_ray_settings_that_cannot_work_are_one_line(tmp_path, overrides, message):
    """Refused before anything starts: no run directory."""
    with pytest.raises(ConfigError) as error:
        run_in_process(tmp_path / "run", 1, [*STATE, *overrides])
    assert str(error.value) == message
    assert not (tmp_path / "run").exists()


def test_collector_ray_without_ray_names_the_cluster_extra(tmp_path, monkeypatch):
    """Ray hidden from the import system: one line naming the extra that installs it."""
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "ray" else real(name, *a))
    with pytest.raises(ConfigError) as error:
        run_in_process(tmp_path / "run", 1, [*STATE, "collector=ray", "workers=2"])
    assert str(error.value) == ("override: collector: 'ray' needs Ray, from the cluster extra: "
                                "pip install -e '.[cluster]'")
    assert not (tmp_path / "run").exists()


@pytest.mark.slow  # needs the cluster extra, which make test-slow installs
def test_a_ray_address_where_nothing_answers_is_one_line(tmp_path):
    """A port nobody listens on: one line naming ray_address, at once, no run directory."""
    address = f"127.0.0.1:{ray_cluster.free_port()}"
    with pytest.raises(ConfigError) as error:
        run_in_process(tmp_path / "run", 1, [*STATE, "collector=ray", "workers=2",
                                             f"ray_address={address}"])
    assert str(error.value) == (f"override: ray_address: nothing answers at {address} "
                                "(Connection refused)")
    assert not (tmp_path / "run").exists()


def local_collectors(tmp_path, workers: int, actor: torch.nn.Module | None = None):
    """The run's learner and ``workers`` remote collectors' :class:`LaneKeepingCollector` built
    here as Ray builds them there (each with a copy of the policy), without Ray."""
    config = resolve_config(compose_config([*TINY, *STATE, f"run_dir={tmp_path / 'run'}"]))
    env, learner, _, _ = build_run(config)
    share = NUM_ENVS // workers
    collectors = [LaneKeepingCollector(
        worker_env(config, w * share, share), copy.deepcopy(learner.actor),
        frames_per_batch=share * ROLLOUT, total_frames=-1, sample_seed=w,
        exploration_type=ExplorationType.RANDOM, auto_register_policy_transforms=False)
        for w in range(workers)]
    return env, learner, collectors


def test_collector_batches_merge_into_the_local_layout(tmp_path):
    """Two collectors' batches merged: the keys, shapes and dtypes of a local collection of
    the same simulations, which spawn as they would locally, with each row one simulation's
    consecutive steps."""
    env, learner, collectors = local_collectors(tmp_path, 2)
    local, _ = collect(env, learner.actor, env.reset(), ROLLOUT)
    merged = merge_batches(torch.stack([next(iter(c)) for c in collectors]))

    def layout(batch):
        return {key: (batch.get(key).shape, batch.get(key).dtype)
                for key in batch.keys(True, True)}

    assert layout(merged) == layout(local)
    assert merged.batch_size == local.batch_size == (NUM_ENVS, ROLLOUT)
    assert torch.equal(merged["state"][:, 0], local["state"][:, 0])  # the same spawns
    follows = merged["next", "state"][:, :-1] == merged["state"][:, 1:]
    assert (follows.all(-1) | merged["next", "done"][:, :-1, 0]).all()


def test_collectors_act_with_the_weights_sent_to_them(tmp_path):
    """Weights sent as the trainer sends them (``update_policy_weights_`` with the policy's
    weights) reach a collector's own copy of the policy: a policy made to always turn one way
    is followed at once."""
    _, learner, (collector,) = local_collectors(tmp_path, 1)
    head = learner.actor.module[0].module[-1]  # the logits layer
    batches = iter(collector)
    for action in (0, 2):
        with torch.no_grad():
            head.bias.copy_(torch.full((3,), -100.0))
            head.bias[action] = 100.0
        collector.update_policy_weights_(TensorDict.from_module(learner.actor).data)
        assert (next(batches)["action"] == action).all()


# ----- through a Ray head on 127.0.0.1 ------------------------------------------------------
@pytest.fixture(scope="module")
def ray_head(tmp_path_factory):
    """A Ray head bound to 127.0.0.1 with 2 CPUs (:func:`ray_cluster.ray_head`) for this
    module's runs."""
    pytest.importorskip("ray")  # the cluster extra (make test-slow)
    with ray_cluster.ray_head(tmp_path_factory.mktemp("ray") / "ray_head.log") as head:
        yield head


def train_through_ray(run_dir: Path, iterations: int, *extra: str, head=None
                      ) -> tuple[str, set[tuple[str, int]]]:
    """``python -m crllk.train`` of ``iterations`` tiny iterations with two remote collectors,
    on ``head`` (a :func:`ray_head`) or a private Ray instance; returns its output and the
    addresses it (and the head) listened on. The trainer gets the head's token but not
    RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER, which it sets itself; without a head, no RAY_ variable."""
    args = [*TINY, *STATE, "collector=ray", "workers=2", f"run_dir={run_dir}",
            f"total_frames={iterations * FRAMES_PER_ITERATION}", *extra]
    if head is None:
        env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
        roots = []
    else:
        address, env, process = head
        env = {k: v for k, v in env.items() if k not in ray_cluster.RAY_LOCAL_ONLY}
        args.append(f"ray_address={address}")
        roots = [process.pid]
    log = run_dir.with_name(f"{run_dir.name}.log")
    with log.open("w") as out:
        trainer = subprocess.Popen([sys.executable, "-m", "crllk.train", *args], cwd=REPO,
                                   env=env, stdout=out, stderr=subprocess.STDOUT)
    listening = set()
    deadline = time.monotonic() + RAY_RUN_S
    while trainer.poll() is None:
        if time.monotonic() > deadline:
            trainer.kill()
            pytest.fail("the run did not end: " + log.read_text()[-3000:])
        listening |= ray_cluster.listening([*roots, trainer.pid])
        time.sleep(0.5)
    output = log.read_text()
    assert trainer.returncode == 0, output[-3000:]
    return output, listening


@pytest.fixture(scope="module")
def ray_run(ray_head, tmp_path_factory):
    """A tiny run of two iterations, with an evaluation at the end, collected by two remote
    collectors of one simulation each; its directory, output and the addresses listened on."""
    run_dir = tmp_path_factory.mktemp("ray_run") / "run"
    output, listening = train_through_ray(run_dir, 2, "eval.every=2", "eval.episodes=2",
                                          "eval.num_envs=2", head=ray_head)
    return run_dir, output, listening


@pytest.mark.slow
def test_remote_collectors_train_a_tiny_run(ray_head, ray_run):
    """Two iterations of 16 frames from the collectors: the metrics rows with the episodes
    that finished (horizon 12), the driver's evaluation and checkpoint (without simulator
    state), the collectors' own count of the frames they stepped, and nothing listening
    beyond 127.0.0.1."""
    run_dir, output, listening = ray_run
    rows = read_rows(run_dir / "metrics.csv")
    assert [int(r["iteration"]) for r in rows] == [1, 2]
    assert [int(r["frames"]) for r in rows] == [FRAMES_PER_ITERATION, 2 * FRAMES_PER_ITERATION]
    assert sum(int(r["episodes"]) for r in rows) >= NUM_ENVS
    assert any(math.isfinite(float(r["J_R"])) for r in rows)
    assert all(math.isfinite(float(r["loss_objective"])) for r in rows)
    assert len(read_rows(run_dir / "eval.csv")) == 1
    state = load_checkpoint(run_dir / "checkpoints" / "last.pt")
    assert (state["iteration"], state["frames"]) == (2, 2 * FRAMES_PER_ITERATION)
    assert state["env"] is None and state["carry"] is None
    address = ray_head[0]
    assert (f"ray: 2 remote collectors on the Ray cluster at {address}, 1 of the 2 simulations "
            "each") in output
    assert f"ray: 2 remote collectors stepped {2 * FRAMES_PER_ITERATION} frames" in output
    assert listening and {ip for ip, _ in listening} <= ray_cluster.LOOPBACK, listening


@pytest.mark.slow
def test_a_ray_run_resumes_from_its_checkpoint(ray_run, tmp_path):
    """A copy of the two-iteration run resumed for a third iteration by collectors on a
    private Ray instance (listening on 127.0.0.1 only) continues from its checkpoint (the
    counters, and the optimiser: its step count goes on) with fresh episodes; then resumed in
    this process (collector=local) for a fourth."""
    run_dir = tmp_path / "run"
    shutil.copytree(ray_run[0], run_dir)
    steps_per_iteration = load_checkpoint(run_dir / "checkpoints" / "last.pt")[
        "optimizer"]["state"][0]["step"] / 2
    output, listening = train_through_ray(run_dir, 3, "resume=true")
    assert ("ray: 2 remote collectors on a private Ray instance on 127.0.0.1, 1 of the 2 "
            "simulations each") in output
    assert (f"resuming {run_dir} at iteration 2, {2 * FRAMES_PER_ITERATION} frames (fresh "
            "episodes: the checkpoint holds no simulator state)") in output
    assert listening and {ip for ip, _ in listening} <= ray_cluster.LOOPBACK, listening
    state = load_checkpoint(run_dir / "checkpoints" / "last.pt")
    assert (state["iteration"], state["frames"]) == (3, 3 * FRAMES_PER_ITERATION)
    assert state["optimizer"]["state"][0]["step"] == 3 * steps_per_iteration
    assert [int(r["iteration"]) for r in read_rows(run_dir / "metrics.csv")] == [1, 2, 3]

    run_in_process(run_dir, 4, [*STATE, "resume=true"])
    state = load_checkpoint(run_dir / "checkpoints" / "last.pt")
    assert state["iteration"] == 4 and state["env"] is not None
    assert [int(r["iteration"]) for r in read_rows(run_dir / "metrics.csv")] == [1, 2, 3, 4]


@pytest.mark.slow
def test_more_collectors_than_the_cluster_has_cpus_is_one_line(ray_head, tmp_path):
    """Four collectors on a head of two CPUs: one line naming workers, before the run
    directory is made."""
    address, env, _ = ray_head
    done = subprocess.run(
        [sys.executable, "-m", "crllk.train", *TINY, *STATE, "num_envs=4", "workers=4",
         "collector=ray", f"ray_address={address}", f"run_dir={tmp_path / 'run'}"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=RAY_RUN_S)
    assert done.returncode == 2, done.stderr[-3000:]
    assert done.stderr.strip().splitlines()[-1] == (
        f"error: override: workers: the Ray cluster at {address} has 2 CPUs, fewer than the 4 "
        "the remote collectors need")
    assert not (tmp_path / "run").exists()
