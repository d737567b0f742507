"""Tiny-budget smoke runs of the command-line entry points."""

from __future__ import annotations

import subprocess
import sys

import mujoco
import numpy as np
import pytest
from PIL import Image

from crllk import demo, pictures


def test_demo_writes_pictures_and_standalone_scenes(tmp_path, capsys):
    """`python -m crllk.demo` drives, prints a table row per map, writes pictures and an MJCF
    scene that MuJoCo loads on its own."""
    demo.main(["--out", str(tmp_path), "--maps", "small_loop", "--steps", "12"])
    printed = capsys.readouterr().out
    assert "small_loop" in printed and "lane cost" in printed
    for suffix in ("topdown", "camera", "camera_full", "chase"):
        image = np.asarray(Image.open(tmp_path / f"small_loop_{suffix}.png"))
        assert image.ndim == 3 and image.std() > 5  # a real picture, not a blank
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "mjcf" / "small_loop.xml"))
    assert model.nu == 2 and model.ncam >= 3


def test_pictures_command_writes_each_requested_map(tmp_path):
    """`python -m crllk.pictures` writes the four pictures per map."""
    pictures.main(["--out", str(tmp_path), "--maps", "obstacle_loop", "--steps", "8"])
    written = sorted(p.name for p in tmp_path.glob("*.png"))
    assert written == [f"obstacle_loop_{s}.png"
                       for s in ("camera", "camera_full", "chase", "topdown")]


def test_bench_prints_each_figure_with_its_bound(capsys):
    """`python -m crllk.bench` at a tiny budget prints the five figures and three ratios
    (the randomised pixel env against the same env without randomisation among them)."""
    from crllk.bench import cli as bench

    bench.main(["--steps", "20"])
    printed = capsys.readouterr().out
    assert "raw MuJoCo physics" in printed and "env, pixel observations" in printed
    assert printed.count("met") + printed.count("MISSED") == 3
    assert "env, pixels, randomize=default" in printed


def test_bench_times_each_part_of_the_randomisation(capsys):
    """``--randomize-parts``: one ratio per part of randomize=default and one for all of it,
    each against the same env without randomisation; each part sets only its own fields."""
    from crllk.bench import cli as bench
    from crllk.tasks.config import load_task_config

    bench.main(["--steps", "10", "--randomize-parts"])
    printed = capsys.readouterr().out
    for part in [*bench.RANDOMIZED_PARTS, "all (default)"]:
        assert f"env, pixels, randomize: {part} " in printed, part
    covered = [name for names in bench.RANDOMIZED_PARTS.values() for name in names]
    preset = bench.PRESETS["default"]
    set_in_preset = [f for f, v in vars(preset).items() if v not in (None, 0, 0.0)]
    assert sorted(covered) == sorted(set_in_preset)  # the parts cover the preset, once each
    lighting = load_task_config("small_loop", {"randomize": bench.randomization_part(
        "lighting")}).randomize
    assert lighting.light_tilt == preset.light_tilt and lighting.jpeg_quality is None


def test_bench_times_traffic_against_the_same_task_without_movers(capsys):
    """``--traffic``: the batched pixel env with the task's movers against the same task
    without them (and without the headway constraint, which needs vehicles); refused in one
    line for a task without traffic."""
    from crllk.bench import cli as bench

    assert bench.without_traffic("traffic_loop") == {"traffic": None,
                                                     "constraints": ["lane", "collision"]}
    bench.main(["--task", "traffic_loop", "--steps", "8", "--num-envs", "2", "--traffic"])
    printed = capsys.readouterr().out
    assert "make_env pixels without movers, num_envs=2" in printed
    assert "make_env pixels with traffic, num_envs=2" in printed
    with pytest.raises(SystemExit) as stop:
        bench.main(["--steps", "8", "--traffic"])
    assert stop.value.code == 2
    assert "--traffic needs a task with traffic" in capsys.readouterr().err


def test_bench_batched_and_training_figures(capsys, tmp_path):
    """The batched-environment and training figures, and the time to satisfy both constraints
    read from a run's eval.csv, at a tiny budget."""
    from crllk.bench import cli as bench

    run = tmp_path / "run"
    run.mkdir()
    (run / "eval.csv").write_text("iteration,frames,time_s,satisfied\n10,100,5.0,0\n"
                                  "20,200,12.5,1\n30,300,20.0,1\n")
    bench.main(["--steps", "8", "--num-envs", "2", "--batched", "--training",
                "--iterations", "1", "--overrides", "num_envs=2", "rollout_steps=4",
                "ppo.minibatch_size=4", "ppo.epochs=1", "--runs", str(run)])
    printed = capsys.readouterr().out
    assert "make_env state, num_envs=2" in printed and "make_env pixels, num_envs=2" in printed
    assert "training, state (frames/s)" in printed and "training, pixels (frames/s)" in printed
    assert "training, state, collect_ahead (frames/s)" in printed
    assert printed.count("met") + printed.count("MISSED") == 9
    assert f"{run}: 12 s (0.2 min) at 200 frames" in printed


def test_bench_worker_figures(capsys):
    """``--workers 1 2`` at a tiny budget: collection and training frames/s with one and two
    worker processes, each against the one-process figure, and the main process's shares."""
    from crllk.bench import cli as bench

    bench.main(["--steps", "8", "--workers", "1", "2", "--obs", "state", "--iterations", "1",
                "--overrides", "num_envs=2", "rollout_steps=4", "ppo.minibatch_size=4",
                "ppo.epochs=1"])
    printed = capsys.readouterr().out
    for kind in ("collection", "training"):
        for workers in (1, 2):
            assert f"{kind}, state, workers={workers} (frames/s)" in printed
    assert "main process, state: policy forward on 2 observations" in printed


TINY_TRAINING = ["obs=state", "num_envs=2", "rollout_steps=4", "ppo.minibatch_size=4",
                 "ppo.epochs=1", "task.horizon=12", "eval.num_envs=1"]
"""Trainer overrides small enough for a benchmark's smoke run."""


def test_bench_live_measures_both_blocks(capsys):
    """`python -m crllk.bench.live` at a tiny budget: one block with the live view off, one
    with it served on a free port, and both ratios."""
    from crllk.bench import live

    live.main(["--iterations", "1", "--repetitions", "1", *TINY_TRAINING])
    printed = capsys.readouterr().out
    off, on = (line for line in printed.splitlines() if line.startswith("frames/s, live view"))
    assert float(off.split()[-1]) > 0 and float(on.split()[-1]) > 0
    assert "per wall time, median on / off" in printed and "per CPU time" in printed


@pytest.mark.parametrize(("args", "message"), [
    (["--iterations", "0"], "--iterations: must be at least 1, got 0"),
    (["obs=camera"], "obs: unknown choice 'camera'"),
])
def test_bench_live_bad_input_is_one_line(args, message):
    done = subprocess.run([sys.executable, "-m", "crllk.bench.live", *args],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr[-2000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], done.stderr
    assert "Traceback" not in done.stderr


def test_bench_envs_prints_each_batch_size(capsys):
    """`python -m crllk.bench.envs` at a tiny budget: a row per observation and batch size,
    each with its bound, ratio and verdict."""
    from crllk.bench import envs

    envs.main(["--steps", "3", "--num-envs", "1", "2", "--observations", "state"])
    rows = [line for line in capsys.readouterr().out.splitlines()
            if line.startswith("make_env state")]
    assert [row.split()[2] for row in rows] == ["num_envs=1", "num_envs=2"]
    assert all(row.endswith(("met", "MISSED")) and float(row.split()[3]) > 0 for row in rows)


@pytest.mark.parametrize(("args", "message"), [
    (["--task", "nowhere"], "nowhere: task: unknown task"),
    (["--steps", "0"], "--steps: must be at least 1, got 0"),
])
def test_bench_envs_bad_input_is_one_line(args, message):
    done = subprocess.run([sys.executable, "-m", "crllk.bench.envs", *args],
                          capture_output=True, text=True, timeout=300)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and message in lines[0], done.stderr


def test_rendering_processes_exit_without_egl_noise():
    """Renderers are closed before EGL is terminated: no "Exception ignored" at exit."""
    probe = ("import crllk; env = crllk.load('small_loop', observation='pixels'); "
             "env.reset(); env.physics.render_camera(120, 160)")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "Exception ignored" not in done.stderr and "Traceback" not in done.stderr, done.stderr


@pytest.mark.parametrize(("argv", "problem"), [
    (["--task", "no_such_map"], "no_such_map: task: unknown task"),
    (["--episodes", "0"], "argument --episodes: must be at least 1, got 0"),
    (["--horizon", "0"], "argument --horizon: must be at least 1, got 0"),
    (["--episodes", "two"], "argument --episodes: expected a whole number, got 'two'"),
])
def test_record_command_answers_bad_input_with_one_line(argv, problem, capsys, tmp_path):
    from crllk import record

    with pytest.raises(SystemExit) as exit_info:
        record.main([*argv, "--out", str(tmp_path / "r.rrd")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and problem in err and len(err.splitlines()) == 1, err


@pytest.mark.parametrize(("argv", "problem"), [
    (["--task", "no_such_map"], "no_such_map: task: unknown task"),
    (["--steps", "0"], "argument --steps: must be at least 1, got 0"),
    (["--steps", "-1"], "argument --steps: must be at least 1, got -1"),
    (["--num-envs", "0"], "argument --num-envs: must be at least 1, got 0"),
    (["--iterations", "0"], "argument --iterations: must be at least 1, got 0"),
    (["--workers", "0"], "argument --workers: must be at least 1, got 0"),
    (["--workers", "3", "--overrides", "num_envs=2"],
     "override: workers: must divide num_envs (2) into equal shares, got 3"),
    (["--runs", "RUN"], "--runs: no eval.csv"),
    (["--training", "--overrides", "collector=ray"],
     "--overrides: collector: --training times local collection; time collector=ray with "
     "--workers"),
])
def test_bench_command_answers_bad_input_with_one_line(argv, problem, capsys, tmp_path):
    from crllk.bench import cli as bench

    argv = [str(tmp_path) if a == "RUN" else a for a in argv]
    with pytest.raises(SystemExit) as exit_info:
        bench.main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and problem in err and len(err.splitlines()) == 1, err
