"""A finished run is reused by an experiment only if it was trained as the experiment would
train it now (crllk.experiments.provenance)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import TINY_EXPERIMENT
from omegaconf import OmegaConf

from crllk.errors import ConfigError
from crllk.experiments.provenance import stale_settings
from crllk.experiments.realmaps import map_file
from crllk.experiments.runs import RunSpec, Settings, check_provenance, run_overrides
from crllk.training.compose import compose_config

REPO = Path(__file__).resolve().parents[1]


def _write_run(run_dir: Path, overrides: list[str], drop: tuple[str, ...] = ()) -> Path:
    """A run directory whose config.yaml is what ``overrides`` compose, without ``drop``
    (top-level settings a run trained before they existed would not hold)."""
    config = OmegaConf.to_container(compose_config(overrides), resolve=True)
    for key in drop:
        config.pop(key)
    run_dir.mkdir(parents=True)
    OmegaConf.save(OmegaConf.create(config), run_dir / "config.yaml")
    return run_dir


def test_discrete_runs_on_obstacles_use_the_curve_weight_and_continuous_runs_do_not():
    """The action group sets encounter_curve_weight: 4 for discrete, 1 for the Gaussian
    actions; the command line still wins."""
    def weight(*overrides: str) -> float:
        return compose_config(["task=obstacle_loop", *overrides]).encounter_curve_weight

    assert weight() == weight("agent=CRLLK-D") == weight("agent=PPO-D") == 4.0
    assert weight("agent=CRLLK-C") == weight("agent=PPO-C") == weight("action=stoppable") == 1.0
    assert weight("agent=CRLLK-C", "encounter_curve_weight=2") == 2.0


def test_a_run_from_before_the_curve_weight_is_stale_where_it_meets_obstacles(tmp_path):
    """Without encounter_curve_weight in its file a run trained with 1 (the former default):
    stale on obstacle_loop for a discrete agent, not on a map without objects, not without
    encounter spawns, and not for a continuous agent (whose default is still 1)."""
    obstacles = ["agent=CRLLK-D", "task=obstacle_loop"]
    run = _write_run(tmp_path / "old", obstacles, drop=("encounter_curve_weight",))
    assert stale_settings(run, obstacles) == [("encounter_curve_weight", 1.0, 4.0)]
    plain = ["agent=CRLLK-D", "task=small_loop"]
    assert stale_settings(_write_run(tmp_path / "plain", plain,
                                     drop=("encounter_curve_weight",)), plain) == []
    alone = [*obstacles, "encounters=0"]
    assert stale_settings(_write_run(tmp_path / "alone", alone,
                                     drop=("encounter_curve_weight",)), alone) == []
    continuous = ["agent=CRLLK-C", "task=obstacle_loop"]
    assert stale_settings(_write_run(tmp_path / "c", continuous,
                                     drop=("encounter_curve_weight",)), continuous) == []


def test_what_a_run_learns_is_compared_and_how_it_is_watched_is_not(tmp_path):
    settings = ["agent=CRLLK-D", "task=small_loop"]
    run = _write_run(tmp_path / "run", [*settings, "eval.every=7", "threads=2",
                                        "ppo.lr=0.002", "task.horizon=300"])
    assert sorted(stale_settings(run, settings)) == [("ppo.lr", 0.002, 0.001),
                                                     ("task.horizon", 300, 512)]


def test_a_map_files_objects_decide_whether_encounters_are_compared(tmp_path):
    """A map file's run composes the default task: its own objects come from the file."""
    for name, stale in (("regress_4way_adam", True), ("ETH_small_intersect", False)):
        overrides = ["agent=CRLLK-D", f"task_file={map_file(name)}"]
        run = _write_run(tmp_path / name, overrides, drop=("encounter_curve_weight",))
        expected = [("encounter_curve_weight", 1.0, 4.0)] if stale else []
        assert stale_settings(run, overrides, task_file=map_file(name)) == expected


def test_check_provenance_names_every_stale_run_in_one_line(tmp_path):
    settings = Settings(runs_root=tmp_path, frames=16)
    specs = [RunSpec("CRLLK-D", "obstacle_loop", seed) for seed in (0, 1)]
    for spec in specs:
        _write_run(spec.directory(tmp_path), run_overrides(spec, settings),
                   drop=("encounter_curve_weight",))
    with pytest.raises(ConfigError) as error:
        check_provenance(specs, settings)
    message = str(error.value)
    assert "\n" not in message
    assert message.count("encounter_curve_weight 1.0 (now 4.0)") == 2
    assert "move them aside" in message
    check_provenance([RunSpec("CRLLK-D", "obstacle_loop", 2)], settings)  # not trained: fine


def test_an_experiment_with_other_settings_refuses_the_finished_runs(tiny_experiments,
                                                                       tmp_path):
    """The tiny runs again, with another learning rate: one line, exit 2, nothing trained."""
    runs, _, _ = tiny_experiments
    completed = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "table1", *TINY_EXPERIMENT,
         "ppo.lr=0.0005", "--runs-root", str(runs.parent), "--results", str(tmp_path)],
        cwd=REPO, capture_output=True, text=True, timeout=300)
    assert completed.returncode == 2, completed.stdout + completed.stderr
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in completed.stderr
    assert "ppo.lr 0.001 (now 0.0005)" in lines[0]
    assert not (tmp_path / "pixels" / "table1.json").exists()
