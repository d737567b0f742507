"""The live view of a training run (``live=``): what it logs on the ``iteration`` timeline, read
back from a file sink; training with it on; a live view that cannot start; its settings."""

from __future__ import annotations

import math
import socket

import pyarrow as pa
import pytest
import rerun as rr
from tiny_runs import compose_config, run_in_process

import crllk
from crllk.config import validate
from crllk.errors import ConfigError
from crllk.recording import live
from crllk.recording.live import PREFIX, THRESHOLD, LiveView
from crllk.recording.live import series as live_series
from crllk.recording.recorder import read_recording, record_episodes
from crllk.recording.viewer import free_port
from crllk.tasks.constraints import BUILTIN
from crllk.tasks.follower import FollowerPolicy

CONSTRAINTS = (BUILTIN["lane"], BUILTIN["collision"])
THRESHOLDS = {"lane": 0.5, "collision": 0.02}
SERIES = live_series(CONSTRAINTS)


def series(chunks, path: str) -> dict[int, float]:
    """``iteration`` -> value of the scalar series at ``path``."""
    table = pa.Table.from_batches([b for b in chunks[path] if "iteration" in b.schema.names])
    values = table.column("Scalars:scalars").to_pylist()
    return dict(zip(table.column("iteration").to_pylist(), (v[0] for v in values), strict=True))


def row(iteration: int, **values: float) -> dict[str, float]:
    return {"iteration": iteration, **dict.fromkeys(SERIES, float(iteration)), **values}


def test_iterations_and_recordings_land_on_the_iteration_timeline(tmp_path):
    env = crllk.make_env("small_loop", observation="state", action="duty", seed=0,
                         overrides={"horizon": 10})
    recording = tmp_path / "iteration_000002.rrd"
    record_episodes(env, FollowerPolicy(env), 1, recording, iteration=2)
    env.close()
    view = LiveView([rr.FileSink(tmp_path / "live.rrd")], "live-test", CONSTRAINTS, THRESHOLDS)
    view.log_iteration(row(1, J_R=math.nan))  # no episode ended: no J_R
    view.log_iteration(row(2))
    view.add_recording(recording)
    view.log_iteration(row(3, lambda_lane=0.25))
    view.close()
    chunks = read_recording(tmp_path / "live.rrd")
    assert series(chunks, PREFIX + "J_R") == {2: 2.0, 3: 3.0}
    assert series(chunks, PREFIX + "lambda_lane") == {1: 1.0, 2: 2.0, 3: 0.25}
    for column in SERIES:
        assert set(series(chunks, PREFIX + column)) >= {2, 3}, column
    assert series(chunks, f"{PREFIX}J_coll/{THRESHOLD}") == {1: 0.02, 2: 0.02, 3: 0.02}
    robot = pa.Table.from_batches(chunks["world/robot"])
    assert set(robot.column("iteration").to_pylist()) == {2} and robot.num_rows == 10
    assert "world/robot/camera/image" in chunks and "world/map/tiles" in chunks


def test_the_plots_are_the_learner_s_own_diagnostics(tmp_path):
    """SAC-Lagrangian's losses get plots, PPO's do not (they are not in its metrics.csv); a
    learner's other diagnostics (counters, statistics) are not plotted."""
    sac = ["loss_actor", "loss_qvalue", "loss_alpha", "alpha"]
    names = live_series(CONSTRAINTS, sac)
    assert [c for c in names if c.startswith("loss_")] == ["loss_actor", "loss_qvalue",
                                                            "loss_alpha"]
    assert (names["loss_qvalue"], names["frames_per_s"]) == ("Q-value loss", "frames/s")
    assert "alpha" not in names  # a learner's other diagnostics stay in metrics.csv
    view = LiveView([rr.FileSink(tmp_path / "live.rrd")], "live-sac", CONSTRAINTS, THRESHOLDS,
                    diagnostics=sac)
    view.log_iteration({"iteration": 1, **dict.fromkeys(names, 0.5)})
    view.close()
    chunks = read_recording(tmp_path / "live.rrd")
    assert series(chunks, PREFIX + "loss_qvalue") == {1: 0.5}
    assert PREFIX + "loss_objective" not in chunks


def test_a_missing_recording_is_a_warning(tmp_path, capsys):
    view = LiveView([rr.FileSink(tmp_path / "live.rrd")], "live-test", CONSTRAINTS, THRESHOLDS)
    view.add_recording(tmp_path / "gone.rrd")
    view.close()
    assert "warning: live view:" in capsys.readouterr().err


def test_training_logs_every_iteration_and_recording_to_one_stream(tmp_path, monkeypatch,
                                                                    capsys):
    """``live=serve`` with the server swapped for a file: one stream for the whole run."""
    path = tmp_path / "live.rrd"
    monkeypatch.setattr(live, "server_sink", lambda port: rr.FileSink(path))
    run_in_process(tmp_path / "run", 4, ["live=serve", f"live_port={free_port()}",
                                         "record_every=2"])
    assert "live view: rerun --bind 127.0.0.1 --connect" in capsys.readouterr().out
    chunks = read_recording(path)
    for column in ("lambda_lane", "lambda_collision", "loss_objective", "frames_per_s"):
        assert sorted(series(chunks, PREFIX + column)) == [1, 2, 3, 4]
    robot = pa.Table.from_batches(chunks["world/robot"])
    assert set(robot.column("iteration").to_pylist()) == {2, 4}


def test_training_goes_on_when_the_live_port_is_taken(tmp_path, capsys):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = run_in_process(tmp_path / "run", 2, ["live=serve", f"live_port={port}"])
    assert "warning: live view unavailable" in capsys.readouterr().err
    assert len((run / "metrics.csv").read_text().splitlines()) == 3


@pytest.mark.parametrize(("override", "field"), [
    (["live=always"], "live"), (["live=serve", "live_port=0"], "live_port"),
    (["live=serve", "live_port=70000"], "live_port"), (["live=serve", "viewer=spawn"], "viewer")])
def test_bad_live_settings_are_named(override, field):
    with pytest.raises(ConfigError, match=field):
        validate(compose_config(override))


def test_spawn_without_a_display_serves_and_says_how_to_connect(tmp_path, monkeypatch, capsys):
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(name, raising=False)
    run = run_in_process(tmp_path / "run", 1, ["live=spawn", f"live_port={free_port()}"])
    err = capsys.readouterr().err
    assert "warning: the viewer cannot open a window: no display" in err
    assert "connect a viewer with `rerun --bind 127.0.0.1" in err
    assert len((run / "metrics.csv").read_text().splitlines()) == 2
