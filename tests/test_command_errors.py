"""Bad input to every command: one line ``error: <source>: <field>: <problem>``, a non-zero
exit status, nothing half-written. The corpus grows with every command; bad task and map files
themselves are in ``test_bad_input.py``, bad trainer overrides in ``test_train.py``."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from crllk import evaluate, experiments, pictures, record
from crllk.cli import DEBUG_VARIABLE, exit_status
from crllk.config import validate
from crllk.files import STALE_TEMP_AGE_S, atomic_write_text
from crllk.train import resolve_config
from crllk.training.compose import compose_config
from crllk.training.loop import train

REPO = Path(__file__).resolve().parent.parent
LOOP_MAP = ("tile_size: {size}\ntiles:\n  - [curve_left/W, straight/W, curve_left/N]\n"
            "  - [straight/S, asphalt, straight/N]\n  - [curve_left/S, straight/E, curve_left/E]\n")


def _one_line_error(capsys, status: int, expected_status: int = 2) -> str:
    err = capsys.readouterr().err.strip()
    assert status == expected_status, err
    assert err.startswith("error: ") and len(err.splitlines()) == 1, err
    return err


def _train_status(overrides: list[str]) -> int:
    return exit_status(lambda: train(resolve_config(compose_config(
        ["obs=state", "num_envs=2", "rollout_steps=4", "total_frames=8", "progress=false",
         *overrides]))))


@pytest.fixture
def a_file(tmp_path) -> Path:
    path = tmp_path / "a_file"
    path.write_text("not a folder\n")
    return path


# ----- the trainer ---------------------------------------------------------------------------
@pytest.mark.parametrize(("content", "words"), [
    (b"\x96\xff\x00binary", "not a text file (UTF-8)"),
    (LOOP_MAP.format(size=0.585).encode() + b"tile_size: 0.6\n", "duplicate key 'tile_size'"),
    (LOOP_MAP.format(size=0.05).encode(), "tile_size: must lie in [0.3, 3.0] m"),
    (LOOP_MAP.format(size=5000).encode(), "tile_size: must lie in [0.3, 3.0] m"),
])
def test_trainer_refuses_a_bad_task_file(tmp_path, capsys, content, words):
    task = tmp_path / "task.yaml"
    task.write_bytes(content)
    run_dir = tmp_path / "never"
    err = _one_line_error(capsys, _train_status([f"task={task}", f"run_dir={run_dir}"]))
    assert str(task) in err and words in err
    assert not run_dir.exists()


def test_trainer_refuses_a_run_directory_it_cannot_use(tmp_path, capsys, a_file):
    for run_dir, words in ((a_file, "is a file, not a directory"),
                           (a_file / "run", "cannot create or write the run directory"),
                           (Path("/proc/crllk-run"), "cannot create or write the run directory")):
        err = _one_line_error(capsys, _train_status([f"run_dir={run_dir}"]))
        assert f"run: run_dir: {run_dir}" in err and words in err


def _dead_pid() -> int:
    """The id of a process that has ended."""
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    return ended.pid


def test_resume_removes_what_a_killed_write_left(tmp_path):
    """Temporary files whose writer is gone go; one whose writer runs (an evaluation writing
    into the run meanwhile) stays."""
    run_dir = tmp_path / "run"
    assert _train_status([f"run_dir={run_dir}"]) == 0
    dead = _dead_pid()
    leftovers = [run_dir / f".eval.csv.{dead}-x1.tmp", run_dir / f".config.yaml.{dead}-x2.tmp",
                 run_dir / "checkpoints" / f".last.pt.{dead}-x3.tmp"]
    live = run_dir / f".eval.json.{os.getppid()}-x4.tmp"
    for leftover in (*leftovers, live):
        leftover.write_text("half")
    assert _train_status([f"run_dir={run_dir}", "resume=true", "total_frames=16"]) == 0
    assert not any(leftover.exists() for leftover in leftovers) and live.exists()


# ----- crllk.evaluate ------------------------------------------------------------------------
def test_evaluate_refuses_a_damaged_checkpoint(tmp_path, capsys):
    run_dir = tmp_path / "run"
    (run_dir / "checkpoints").mkdir(parents=True)
    config = validate(compose_config(["obs=state"]))
    OmegaConf.save(OmegaConf.structured(config), run_dir / "config.yaml")
    (run_dir / "checkpoints" / "last.pt").write_bytes(b"PK\x03\x04 truncated")
    err = _one_line_error(capsys, exit_status(lambda: evaluate.main(
        [f"run={run_dir}", "episodes=1", "num_envs=1"])))
    assert "last.pt" in err and "not a readable checkpoint" in err
    assert not (run_dir / "eval.json").exists()


def test_evaluate_checks_where_it_writes_before_evaluating(tmp_path, capsys, a_file):
    err = _one_line_error(capsys, exit_status(lambda: evaluate.main(
        ["follower=true", "episodes=1", f"out={a_file / 'out.json'}"])))
    assert "evaluate: out:" in err and "is a file, not a directory" in err


def test_evaluate_names_an_unknown_setting(capsys):
    err = _one_line_error(capsys, exit_status(lambda: evaluate.main(["follower=true",
                                                                      "colour=blue"])))
    assert err == "error: evaluate: colour: no such setting"


def test_evaluate_names_an_unknown_action_type(capsys):
    err = _one_line_error(capsys, exit_status(lambda: evaluate.main(["teacher=true",
                                                                      "action=wheels"])))
    assert err == ("error: evaluate: action: must be one of discrete, continuous, stoppable, "
                   "duckietown, duty, got 'wheels'")


# ----- crllk.record and pictures of recordings -----------------------------------------------
def test_evaluate_rejects_a_negative_teacher_margin(capsys):
    err = _one_line_error(capsys, exit_status(lambda: evaluate.main(["teacher=true",
                                                                      "margin=-0.01"])))
    assert err.startswith("error: evaluate: margin: must be >= 0")


def test_record_checks_where_it_writes_before_driving(capsys, a_file):
    with pytest.raises(SystemExit) as exit_info:
        record.main(["--task", "small_loop", "--out", str(a_file / "x.rrd")])
    err = _one_line_error(capsys, exit_info.value.code)
    assert "--out" in err and "is a file, not a directory" in err


def test_a_picture_of_a_missing_recording(tmp_path, capsys):
    from crllk.analysis import recording_picture

    err = _one_line_error(capsys, exit_status(lambda: recording_picture.main(
        [str(tmp_path / "none.rrd"), "--out", str(tmp_path / "p.png")])))
    assert err == f"error: {tmp_path / 'none.rrd'}: recording: no such file"


def test_train_names_a_launcher_whose_plugin_is_missing(capsys, monkeypatch):
    """``-m hydra/launcher=ray_local`` without the cluster extra: one line naming the launcher
    and what installs it, before Hydra starts (the plugin is hidden from the import system)."""
    import importlib.util

    from crllk import train

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None
                        if name == "hydra_plugins.hydra_ray_launcher" else real(name, *a))
    with pytest.raises(SystemExit) as exit_info:
        train.check_overrides(["-m", "hydra/launcher=ray_local", "seed=0,1"])
    err = _one_line_error(capsys, exit_info.value.code)
    assert err == ("error: override: hydra/launcher: 'ray_local' needs "
                   "hydra_plugins.hydra_ray_launcher, from the cluster extra: "
                   "pip install -e '.[cluster]'")
    train.check_overrides(["-m", "hydra/launcher=joblib", "seed=0,1"])  # installed: no error


# ----- crllk.experiments ---------------------------------------------------------------------
@pytest.mark.parametrize(("argv", "words"), [
    (["--set", "foo=1"], "override: foo: no such setting"),
    (["--set", "ppo.gamma=2"], "override: ppo.gamma: must lie in [0, 1]"),
    (["--seeds", "-1"], "override: seed: must be >= 0"),
])
def test_experiments_check_overrides_before_starting_anything(tmp_path, capsys, argv, words):
    runs = tmp_path / "runs"
    err = _one_line_error(capsys, exit_status(lambda: experiments.main(
        ["table1", "--runs-root", str(runs), "--results", str(tmp_path / "results"), *argv])))
    assert words in err
    assert not runs.exists()


def test_experiments_check_their_folders(tmp_path, capsys, a_file):
    err = _one_line_error(capsys, exit_status(lambda: experiments.main(
        ["table1", "--runs-root", str(a_file / "runs")])))
    assert "experiments: --runs-root:" in err and "is a file, not a directory" in err


# ----- crllk.pictures ------------------------------------------------------------------------
def test_pictures_of_a_map_file_go_to_out(tmp_path):
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "my_loop.yaml").write_text(LOOP_MAP.format(size=0.585))
    out = tmp_path / "out"
    assert exit_status(lambda: pictures.main(["--maps", str(maps / "my_loop.yaml"),
                                              "--out", str(out), "--steps", "4"])) == 0
    assert sorted(p.name for p in out.glob("*.png")) == [
        f"my_loop_{s}.png" for s in ("camera", "camera_full", "chase", "topdown")]
    assert sorted(p.name for p in maps.iterdir()) == ["my_loop.yaml"]


def test_pictures_refuse_an_unknown_map_before_drawing(tmp_path, capsys):
    err = _one_line_error(capsys, exit_status(lambda: pictures.main(
        ["--maps", "small_loop", "nosuch", "--out", str(tmp_path)])))
    assert "nosuch" in err and "unknown task" in err
    assert not list(tmp_path.glob("*.png"))


# ----- every command: errors that are not bad input, files, warnings -------------------------
def test_an_unexpected_error_is_one_line_and_its_traceback_is_a_switch(capsys, monkeypatch):
    def broken() -> None:
        raise RuntimeError("first line\nsecond line")

    monkeypatch.delenv(DEBUG_VARIABLE, raising=False)
    err = _one_line_error(capsys, exit_status(broken), expected_status=1)
    assert err == f"error: RuntimeError: first line second line ({DEBUG_VARIABLE}=1 shows where)"
    monkeypatch.setenv(DEBUG_VARIABLE, "1")
    with pytest.raises(RuntimeError, match="first line"):
        exit_status(broken)


def test_an_atomic_write_removes_the_leftovers_of_killed_writes(tmp_path):
    """Leftovers of the same file whose writer is gone (or that nobody touched for a day) go;
    another file's, and those of writers still running, stay."""
    target = tmp_path / "eval.json"
    dead = _dead_pid()
    leftovers = [tmp_path / f".eval.json.{dead}-abc123.tmp", tmp_path / ".eval.json.x.tmp"]
    kept = [tmp_path / f".metrics.csv.{dead}-abc.tmp", tmp_path / ".eval.json.y.tmp",
            tmp_path / f".eval.json.{os.getppid()}-live.tmp"]
    for path in (*leftovers, *kept):
        path.write_text("half")
    day_ago = time.time() - STALE_TEMP_AGE_S - 60
    os.utime(leftovers[1], (day_ago, day_ago))
    atomic_write_text(target, "{}\n")
    assert target.read_text() == "{}\n"
    assert not any(p.exists() for p in leftovers) and all(p.exists() for p in kept)


def test_map_warnings_are_one_line(tmp_path):
    """An unknown map key is a one-line warning on stderr, as a user of any command sees it."""
    path = tmp_path / "map.yaml"
    path.write_text(LOOP_MAP.format(size=0.585) + "version: 2\ncolour: blue\n")
    done = subprocess.run(
        [sys.executable, "-c", f"import crllk; crllk.maps.load_map({str(path)!r})"],
        capture_output=True, text=True, timeout=120, cwd=REPO,
        env={**os.environ, "PYTHONWARNINGS": "default"})
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == f"warning: {path}: colour: unknown map key, ignored"


def test_a_ray_launcher_sweep_keeps_ray_on_loopback(monkeypatch):
    """``-m hydra/launcher=ray_local`` (or the plugin's own ``ray``): the trainer sets the
    variable that keeps Ray on 127.0.0.1 before Ray is imported, and leaves a value the user
    set alone."""
    from crllk.network import RAY_LOCAL_ONLY, keep_ray_launcher_local

    (key, local), = RAY_LOCAL_ONLY.items()
    monkeypatch.delenv(key, raising=False)
    assert not keep_ray_launcher_local(["-m", "seed=0,1"])
    assert key not in os.environ
    assert keep_ray_launcher_local(["-m", "hydra/launcher=ray_local", "seed=0,1"])
    assert os.environ[key] == local
    for plugin_s_own in ("hydra/launcher=ray", "+hydra/launcher=ray_aws"):
        monkeypatch.delenv(key)
        assert keep_ray_launcher_local(["-m", plugin_s_own, "seed=0,1"])
        assert os.environ[key] == local
    monkeypatch.setenv(key, "1")
    assert not keep_ray_launcher_local(["-m", "hydra/launcher=ray_local"])
    assert os.environ[key] == "1"
