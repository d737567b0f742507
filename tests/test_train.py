"""The trainer: a tiny run for every algo × action × obs, checkpoints, exact resume, bad input."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import ray_cluster
from omegaconf import OmegaConf
from tiny_runs import (
    FRAMES_PER_ITERATION,
    NUM_ENVS,
    TINY,
    assert_same_runs,
    compose_config,
    held_by_another_process,
    read_rows,
    run_in_process,
)

from crllk.config import validate
from crllk.errors import ConfigError
from crllk.training.checkpoints import load_checkpoint

REPO = Path(__file__).resolve().parents[1]


def run_command(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "crllk.train", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("obs", ["state", "pixels"])
@pytest.mark.parametrize("action", ["discrete", "continuous"])
@pytest.mark.parametrize("algo", ["crllk", "ppo"])
def test_tiny_run_of_every_variant(tmp_path, algo, action, obs):
    run = run_in_process(tmp_path / "run", 3, [f"algo={algo}", f"action={action}", f"obs={obs}",
                                                "eval.every=3", "eval.episodes=2",
                                                "eval.num_envs=2"])
    rows = read_rows(run / "metrics.csv")
    assert [int(r["iteration"]) for r in rows] == [1, 2, 3]
    assert int(rows[-1]["frames"]) == 3 * FRAMES_PER_ITERATION
    for row in rows:
        assert all(math.isfinite(float(row[k])) for k in ("loss_objective", "loss_critic",
                                                          "loss_cost_critic", "entropy"))
    # horizon 12 with 8 steps per iteration: episodes finish by iteration 2
    assert sum(int(r["episodes"]) for r in rows) >= NUM_ENVS
    if action == "discrete":
        fractions = [float(rows[0][f"action_{n}"]) for n in ("left", "right", "straight")]
        assert sum(fractions) == pytest.approx(1.0)
    lambdas = [float(r["lambda_lane"]) for r in rows]
    if algo == "ppo":  # frozen fixed weights
        assert lambdas == [1.0, 1.0, 1.0]
        expected = 4.0 if action == "discrete" else 40.0
        assert {float(r["lambda_collision"]) for r in rows} == {expected}
    else:
        assert all(v >= 0.0 for v in lambdas)
    evaluation = read_rows(run / "eval.csv")
    assert len(evaluation) == 1 and int(evaluation[0]["episodes"]) == 2
    state = load_checkpoint(run / "checkpoints" / "last.pt")
    assert state["iteration"] == 3 and state["frames"] == 3 * FRAMES_PER_ITERATION
    assert set(state["critics"]) == {"reward", "lane", "collision"}
    assert (run / "config.yaml").exists()


@pytest.mark.parametrize(("every", "final", "iterations"), [
    (2, True, [2, 3]), (2, False, [2]), (0, True, [3]), (0, False, [])])
def test_evaluations_are_periodic_and_at_the_end(tmp_path, every, final, iterations):
    """``eval.every`` iterations apart (0: none), and with ``eval.final`` one at the end."""
    run = run_in_process(tmp_path / "run", 3, ["obs=state", f"eval.every={every}",
                                               f"eval.final={str(final).lower()}",
                                               "eval.episodes=2", "eval.num_envs=2"])
    rows = read_rows(run / "eval.csv") if (run / "eval.csv").exists() else []
    assert [int(r["iteration"]) for r in rows] == iterations


def test_multiplier_rises_while_the_constraint_is_violated(tmp_path):
    """An untrained policy leaves the road: λ_coll must grow from 0 by dual ascent."""
    run = run_in_process(tmp_path / "run", 3, ["algo.constraints.collision.step_size=0.5",
                                               "obs=state", "num_envs=4", "rollout_steps=96",
                                               "task.horizon=512", "eval.final=false"],
                         frames_per_iteration=4 * 96)
    rows = read_rows(run / "metrics.csv")
    collisions = [float(r["J_coll"]) for r in rows if int(r["episodes"]) > 0]
    assert collisions and max(collisions) > 0.02
    assert float(rows[-1]["lambda_collision"]) > 0.0


def test_a_third_constraint_is_configuration_alone(tmp_path):
    """The lane-crossing cost of C-CRLLK, enabled by overrides: its cost reaches the episode
    statistics, its multiplier rises while crossings exceed the threshold, and metrics.csv,
    eval.csv and the checkpoint carry it."""
    run = run_in_process(tmp_path / "run", 3, [
        "obs=state", "num_envs=4", "rollout_steps=96", "task.horizon=512",
        "task.constraints=[lane,collision,crossing]", "algo.constraints.crossing.threshold=0",
        "eval.every=3", "eval.episodes=4", "eval.num_envs=2"], frames_per_iteration=4 * 96)
    rows = read_rows(run / "metrics.csv")
    assert {"J_ccross", "lambda_crossing", "explained_variance_crossing",
            "J_ccross_encounter"} <= set(rows[0])
    crossings = [float(r["J_ccross"]) for r in rows if int(r["episodes"]) > 0]
    assert crossings and max(crossings) > 0.0
    assert float(rows[-1]["lambda_crossing"]) > 0.0
    assert "J_ccross" in read_rows(run / "eval.csv")[0]
    state = load_checkpoint(run / "checkpoints" / "last.pt")
    assert set(state["multipliers"]) == {"lane", "collision", "crossing"}
    assert set(state["critics"]) == {"reward", "lane", "collision", "crossing"}


def test_a_constraint_without_a_multiplier_fails_clearly(tmp_path):
    """A constraint in the task but not in algo.constraints: one line naming the field."""
    with pytest.raises(ConfigError, match=r"algo\.constraints\.crossing: the task constrains"):
        run_in_process(tmp_path / "run", 1, ["obs=state", "~algo.constraints.crossing",
                                             "task.constraints=[lane,collision,crossing]"])


@pytest.mark.parametrize("randomize", [pytest.param("none", marks=pytest.mark.slow), "default"])
def test_killed_run_resumes_exactly(tmp_path, randomize):
    """SIGKILL a real ``python -m crllk.train`` after a checkpoint, resume it, and compare its
    final checkpoint with an uninterrupted run of the same length. The default run kills one
    with per-episode domain randomisation, which restores everything the plain run does and the
    randomisation's draws too; the plain run is among the slow tests."""
    killed = tmp_path / "killed"
    checkpoint = killed / "checkpoints" / "last.pt"
    # The killed run is started long and resumed short; a falling learning rate follows
    # total_frames, so both runs keep it constant here (the schedule is a function of frames).
    constant = ["ppo.anneal_lr=false", f"task.randomize={randomize}"]
    args = [*TINY, *constant, f"run_dir={killed}", "total_frames=100000000"]
    process = subprocess.Popen([sys.executable, "-m", "crllk.train", *args], cwd=REPO,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if checkpoint.exists() and load_checkpoint(checkpoint)["iteration"] >= 2:
                break
            time.sleep(0.2)
        else:
            pytest.fail("no checkpoint at iteration 2 within 120 s")
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    iterations = load_checkpoint(checkpoint)["iteration"] + 2
    total = f"total_frames={iterations * FRAMES_PER_ITERATION}"
    resumed = run_command(*TINY, *constant, f"run_dir={killed}", total, "resume=true")
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert "resuming" in resumed.stdout

    straight = run_in_process(tmp_path / "straight", iterations, constant)
    assert_same_runs(straight, killed, iterations)


def test_command_line_run_prints_its_directory(tmp_path):
    result = run_command(*TINY, f"run_dir={tmp_path / 'cli'}", "total_frames=16",
                         "task=obstacle_loop", "obs=state", "eval.episodes=100",
                         "eval.num_envs=10")  # crllk.evaluate's settings
    assert result.returncode == 0, result.stderr[-2000:]
    assert f"run directory: {tmp_path / 'cli'}" in result.stdout
    assert (tmp_path / "cli" / "metrics.csv").exists()
    written = json.loads((tmp_path / "cli" / "eval.json").read_text())  # the last evaluation
    assert written["evaluation"]["episodes"] == 100 and written["source"]["frames"] == 16


def test_existing_run_is_not_overwritten(tmp_path):
    run_in_process(tmp_path / "run", 1)
    with pytest.raises(ValueError, match="resume=true"):
        run_in_process(tmp_path / "run", 1)


@pytest.mark.parametrize(("override", "expected"), [
    ("task=no_such_map", "override: task: unknown choice 'no_such_map' (choices: "
                         "obstacle_loop, pedestrian_loop, small_loop, traffic_loop, zigzag)"),
    ("algo.constraints.lane.threshold=-1", "algo.constraints.lane.threshold: must be >= 0"),
    ("total_frames=many", "override: total_frames: Value 'many' of type 'str' could not be "
                          "converted to Integer"),
    ("obs=camera", "override: obs: unknown choice 'camera' (choices: pixels, state)"),
    ("algo=sac", "override: algo: unknown choice 'sac' (choices: crllk, ppo, sac_lagrangian)"),
    ("foo=1", "override: foo: no such setting"),
    ("ppo.momentum=0.9", "override: ppo.momentum: no such setting"),
    ("seed", "override: seed: cannot parse this override"),
    ("ppo.gamma=1.5", "ppo.gamma: must lie in [0, 1]"),
    ("obs.history=0", "obs.history: must be > 0"),
    ("algo.constraints.collision.target=0.05", "algo.constraints.collision.target: must be "
                                               "between 0 and the threshold (0.02), got 0.05"),
])
def test_bad_override_fails_clearly(tmp_path, override, expected):
    """One line, exit status 2, nothing written; for a group, the choices that exist."""
    run_dir = tmp_path / "never"
    result = run_command(f"run_dir={run_dir}", "total_frames=16", override)
    assert result.returncode == 2
    assert result.stderr.startswith("error: ") and expected in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not run_dir.exists()


def test_schema_rejects_wrong_types_in_process():
    with pytest.raises(ConfigError, match="override: num_envs: Value 'two'"):
        compose_config(["num_envs=two"])
    with pytest.raises(ConfigError, match="override: num_envs: Value 'two'"):
        validate({**OmegaConf.to_container(compose_config([])), "num_envs": "two"})


def test_ppo_baseline_weights_follow_the_action_type():
    discrete = validate(compose_config(["algo=ppo"]))
    continuous = validate(compose_config(["algo=ppo", "action=continuous"]))
    assert discrete.algo.frozen and discrete.algo.constraints["lane"].initial == 1.0
    assert discrete.algo.constraints["collision"].initial == 4.0
    assert continuous.algo.constraints["collision"].initial == 40.0


def test_a_target_below_the_threshold_moves_dual_ascent_not_the_verdict():
    """target=0.01: an episode mean of 0.015 collisions violates the target, so lambda rises
    by eta (0.015 - 0.01) = 0.5 x 0.005 = 0.0025; without a target it falls (clipped at 0)."""
    from crllk.tasks.config import load_task_config
    from crllk.training.build import build_multipliers

    constraints = load_task_config("obstacle_loop").constraints
    for overrides, expected in ((["algo.constraints.collision.target=0.01"], 0.0025), ([], 0.0)):
        config = validate(compose_config(["task=obstacle_loop", *overrides]))
        multiplier = build_multipliers(config, constraints)["collision"]
        multiplier.update([0.0, 0.01, 0.02, 0.03])  # mean 0.015
        assert multiplier.value == pytest.approx(expected)
        assert config.algo.constraints["collision"].threshold == 0.02


@pytest.mark.parametrize("key", ["task_file", "task"])
def test_broken_task_file_names_file_and_field(tmp_path, key):
    """A task file by path, as ``task_file=PATH`` or ``task=PATH``."""
    broken = tmp_path / "broken.yaml"
    broken.write_text("tile_size: 0.585\ntiles:\n  - [straight/N, stright/N]\nobjects: []\n")
    run_dir = tmp_path / "never"
    result = run_command(f"run_dir={run_dir}", "total_frames=16", f"{key}={broken}")
    assert result.returncode == 2
    assert f"error: {broken}: tiles" in result.stderr and "stright" in result.stderr
    assert "Traceback" not in result.stderr
    assert not run_dir.exists()


def test_task_settings_given_with_a_task_file_are_refused(tmp_path):
    """``task=<file>.yaml task.horizon=12``: the file holds the task's settings, so the change
    would be dropped; it is refused in one line instead."""
    result = run_command(f"run_dir={tmp_path / 'never'}", "total_frames=16",
                         f"task={REPO / 'tasks' / 'small_loop.yaml'}", "task.horizon=12")
    assert result.returncode == 2
    assert result.stderr.strip() == ("error: override: task.horizon: a task file's settings are "
                                     "set in the file; task.* changes apply to named tasks (edit "
                                     "a copy of the file)")
    assert not (tmp_path / "never").exists()


def test_a_run_being_trained_cannot_be_trained_twice(tmp_path):
    """A second process on a locked run directory stops with a clear message, writes nothing,
    and the lock goes with the process that held it."""
    run_dir = tmp_path / "run"
    with held_by_another_process("lock_run_dir(Path(sys.argv[1]))", run_dir):
        result = run_command(*TINY, f"run_dir={run_dir}", "resume=true", "total_frames=16")
        assert result.returncode == 2
        assert "is being trained by another process" in result.stderr
        assert not (run_dir / "metrics.csv").exists()
    result = run_command(*TINY, f"run_dir={run_dir}", "resume=true", "total_frames=16")
    assert result.returncode == 0, result.stderr


def test_imitation_weight_schedule():
    """teacher.coeff 1 falling to teacher.final 0.1 over 100 frames, then staying there."""
    from crllk.algos.schedules import imitation_coeff

    config = validate(compose_config(["teacher.coeff=1.0", "teacher.final=0.1",
                                      "teacher.frames=100"]))
    assert [imitation_coeff(config, f) for f in (0, 50, 100, 1000)] == pytest.approx(
        [1.0, 0.55, 0.1, 0.1])
    off = validate(compose_config(["teacher.coeff=0", "teacher.final=0"]))
    assert imitation_coeff(off, 0) == 0.0


def test_learning_rate_schedule():
    """ppo.lr 0.002 annealed over 1000 frames to a tenth of it; constant without anneal_lr;
    a final fraction outside [0, 1] is refused."""
    from crllk.algos.schedules import learning_rate

    config = validate(compose_config(["ppo.lr=0.002", "ppo.anneal_lr=true",
                                      "ppo.lr_final_fraction=0.1", "total_frames=1000"]))
    assert [learning_rate(config, f) for f in (0, 500, 1000, 2000)] == pytest.approx(
        [0.002, 0.0011, 0.0002, 0.0002])
    constant = validate(compose_config(["ppo.lr=0.002", "total_frames=1000",
                                        "ppo.anneal_lr=false"]))
    assert learning_rate(constant, 900) == 0.002
    with pytest.raises(ConfigError, match=r"ppo\.lr_final_fraction"):
        validate(compose_config(["ppo.lr_final_fraction=1.5"]))


def test_entropy_bonus_schedule():
    """ppo.entropy_coeff 0.02 falling over 1000 frames to a quarter of it; constant by default;
    a final fraction outside [0, 1] is refused."""
    from crllk.algos.schedules import entropy_coeff

    config = validate(compose_config(["ppo.entropy_coeff=0.02", "total_frames=1000",
                                      "ppo.entropy_final_fraction=0.25"]))
    assert [entropy_coeff(config, f) for f in (0, 500, 1000, 2000)] == pytest.approx(
        [0.02, 0.0125, 0.005, 0.005])
    constant = validate(compose_config(["ppo.entropy_coeff=0.02", "total_frames=1000"]))
    assert entropy_coeff(constant, 900) == pytest.approx(0.02)
    with pytest.raises(ConfigError, match=r"ppo\.entropy_final_fraction"):
        validate(compose_config(["ppo.entropy_final_fraction=-0.1"]))


def test_teacher_and_encounters_reach_the_training_run(tmp_path):
    """On obstacle_loop with every training episode an encounter, metrics.csv reports the
    encounter episodes apart (J_* stay empty: no episode of the task's own spawns), the
    imitation loss is positive, and the evaluation env keeps the task's own spawns."""
    run = run_in_process(tmp_path / "run", 3, ["task=obstacle_loop", "obs=state",
                                               "encounters=1.0", "teacher.coeff=1.0",
                                               "eval.every=3", "eval.episodes=2",
                                               "eval.num_envs=2"])
    rows = read_rows(run / "metrics.csv")
    assert sum(int(r["encounter_episodes"]) for r in rows) >= NUM_ENVS
    assert all(int(r["episodes"]) == 0 and r["J_coll"] == "nan" for r in rows)
    assert all(float(r["loss_imitation"]) > 0 for r in rows)
    assert float(rows[-1]["lambda_collision"]) == 0.0  # no episode of the task's own spawns
    assert int(read_rows(run / "eval.csv")[0]["episodes"]) == 2


@pytest.mark.parametrize(("override", "field"), [("encounters=1.5", "encounters"),
                                               ("teacher.coeff=-1", "teacher.coeff"),
                                               ("teacher.final=nan", "teacher.final")])
def test_bad_teacher_and_encounter_overrides(override, field):
    from crllk.errors import ConfigError

    with pytest.raises(ConfigError, match=field):
        validate(compose_config([override]))


def test_last_evaluation_row_agrees_with_crllk_evaluate(tmp_path):
    """The evaluation made at the end of training is the one python -m crllk.evaluate makes
    of the last checkpoint with the same episodes: same numbers, same verdict; the trainer's
    command writes it as eval.json, the document crllk.evaluate writes."""
    from crllk.evaluation.runs import evaluate_run, write_final_evaluation

    run = run_in_process(tmp_path / "run", 2, ["task=obstacle_loop", "obs=state",
                                               "eval.every=5", "eval.episodes=4",
                                               "eval.num_envs=2", "task.horizon=40"],
                         on_final_evaluation=write_final_evaluation)
    last = read_rows(run / "eval.csv")[-1]
    assert int(last["iteration"]) == 2  # not a multiple of eval.every: the final evaluation
    written = json.loads((run / "eval.json").read_text())
    document = evaluate_run(run, episodes=4, num_envs=2, name="again")
    summary = document["summary"]
    for key in ("J_R", "J_clane", "J_coll"):
        assert float(last[key]) == pytest.approx(summary[key], rel=1e-5), key
    assert bool(int(last["satisfied"])) == summary["satisfied"]
    assert written == document
    assert written["source"]["frames"] == 2 * FRAMES_PER_ITERATION


def test_task_takes_a_name_or_a_path_when_composed(tmp_path):
    """``task=PATH`` composes as ``task_file=PATH`` wherever the trainer's configuration is
    composed (the trainer, the benchmarks), and a missing file is named."""
    path = REPO / "tests" / "data" / "small_loop_cw.yaml"
    config = validate(compose_config([f"task={path}"]))
    assert config.task_file == str(path) and config.task_source() == str(path)
    assert validate(compose_config(["task=zigzag"])).task_source() == "zigzag"
    with pytest.raises(ConfigError, match=r"task_file: no such file: .*nosuch\.yaml"):
        validate(compose_config([f"task={tmp_path / 'nosuch.yaml'}"]))


def test_a_multirun_trains_every_combination_in_parallel(tmp_path):
    """``-m`` with 2 seeds x 2 thresholds: four runs through the joblib launcher, each in the
    run directory its swept values name, each with its own settings."""
    result = subprocess.run(
        [sys.executable, "-m", "crllk.train", "-m", "seed=0,1",
         "algo.constraints.lane.threshold=0.5,0.75",
         f"run_dir={tmp_path}/s${{seed}}-a${{algo.constraints.lane.threshold}}", "obs=state",
         "num_envs=2", "rollout_steps=4", "total_frames=8", "progress=false", "eval.final=false"],
        cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    runs = sorted(p.name for p in tmp_path.iterdir() if (p / "metrics.csv").exists())
    assert runs == ["s0-a0.5", "s0-a0.75", "s1-a0.5", "s1-a0.75"]
    saved = OmegaConf.load(tmp_path / "s1-a0.75" / "config.yaml")
    assert saved.seed == 1 and saved.algo.constraints.lane.threshold == 0.75


@pytest.mark.slow
def test_a_multirun_through_submitit_runs_each_job(tmp_path):
    """The SLURM path tried here: ``hydra/launcher=submitit_local`` (the ``cluster`` extra)
    runs each job of the sweep as a submitit job into its own run directory."""
    result = subprocess.run(
        [sys.executable, "-m", "crllk.train", "-m", "hydra/launcher=submitit_local", "seed=0,1",
         f"run_dir={tmp_path}/s${{seed}}", "obs=state", "num_envs=2", "rollout_steps=4",
         "total_frames=8", "progress=false", "eval.final=false"],
        cwd=tmp_path, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir() if (p / "metrics.csv").exists()) == [
        "s0", "s1"]


@pytest.fixture
def ray_head(tmp_path):
    """A Ray head bound to 127.0.0.1 (:func:`ray_cluster.ray_head`): its address, the
    environment that reaches it and its process."""
    pytest.importorskip("hydra_plugins.hydra_ray_launcher")  # the cluster extra (make test-slow)
    with ray_cluster.ray_head(tmp_path / "ray_head.log") as head:
        yield head


@pytest.mark.slow
def test_a_multirun_through_ray_runs_each_job_on_a_head_bound_to_127_0_0_1(tmp_path, ray_head):
    """``hydra/launcher=ray_local`` (the ``cluster`` extra) joined to a local head: both jobs of
    the sweep run on Ray workers, each into its own run directory, and neither the head, its
    workers nor the sweep's driver listen anywhere but on 127.0.0.1."""
    address, env, head = ray_head
    runs, log = tmp_path / "runs", tmp_path / "sweep.log"
    with log.open("w") as out:
        sweep = subprocess.Popen(
            [sys.executable, "-m", "crllk.train", "-m", "hydra/launcher=ray_local",
             f"hydra.launcher.ray.init.address={address}", "seed=0,1",
             f"run_dir={runs}/s${{seed}}", "obs=state", "num_envs=2", "rollout_steps=4",
             "total_frames=8", "progress=false", "eval.final=false"],
            cwd=tmp_path, env=env, stdout=out, stderr=subprocess.STDOUT)
    listening = set()
    deadline = time.monotonic() + 600
    while sweep.poll() is None:
        if time.monotonic() > deadline:
            sweep.kill()
            pytest.fail("the sweep did not end: " + log.read_text()[-3000:])
        listening |= ray_cluster.listening([head.pid, sweep.pid])
        time.sleep(0.5)
    assert sweep.returncode == 0, log.read_text()[-3000:]
    assert listening and {ip for ip, _ in listening} <= ray_cluster.LOOPBACK, listening
    assert sorted(p.name for p in runs.iterdir() if (p / "metrics.csv").exists()) == ["s0", "s1"]
    for seed in (0, 1):
        assert OmegaConf.load(runs / f"s{seed}" / "config.yaml").seed == seed


def test_a_map_file_run_is_named_after_its_file():
    """Evaluations and exported policies name a map file's run by the file, not by the
    default task the composition starts from."""
    from crllk.config import validate
    from crllk.training.compose import compose_config

    path = str(Path(__file__).parent / "data/real_maps/duckietown-world/ETH_small_intersect.yaml")
    config = validate(compose_config([f"task={path}"]))
    assert config.task_name == "ETH_small_intersect"
    assert str(config.task_source()) == path
    assert config.default_run_dir().parent.name == "ETH_small_intersect"
    assert validate(compose_config(["task=zigzag"])).task_name == "zigzag"
