"""Recording from the commands: ``record_every`` in training, ``record=true`` in evaluation, and
failures that warn (training) or stop with a clear error (evaluation) instead of crashing."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
from tiny_runs import TINY, run_in_process

from crllk.recording.entities import IMAGE, ROBOT
from crllk.recording.recorder import read_recording

REPO = Path(__file__).resolve().parents[1]


def run_module(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout)


def iteration_values(path: Path) -> set[int]:
    table = pa.Table.from_batches(read_recording(path)[ROBOT])
    return set(table.column("iteration").to_pylist())


def test_training_records_an_episode_every_k_iterations(tmp_path):
    run = run_in_process(tmp_path / "run", 4, ["record_every=2"])
    files = sorted((run / "recordings").glob("*.rrd"))
    assert [f.name for f in files] == ["iteration_000002.rrd", "iteration_000004.rrd"]
    assert iteration_values(files[0]) == {2} and iteration_values(files[1]) == {4}
    chunks = read_recording(files[1])
    robot_rows = sum(batch.num_rows for batch in chunks[ROBOT])
    assert robot_rows == 12  # one evaluation episode of the 12-step horizon
    assert IMAGE in chunks and "lagrange/lane" in chunks


def test_training_goes_on_when_the_recording_cannot_be_written(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "recordings").write_text("a file where the folder should be")
    result = run_module("crllk.train", *TINY, f"run_dir={run_dir}", "total_frames=32",
                        "record_every=1")
    assert result.returncode == 0, result.stderr
    assert "warning: recording at iteration 1 failed" in result.stderr
    assert "recordings" in result.stderr
    assert len((run_dir / "metrics.csv").read_text().splitlines()) == 3


def test_training_without_recordings_never_imports_rerun(tmp_path):
    code = ("import sys; from tiny_runs import run_in_process; "
            f"run_in_process(__import__('pathlib').Path({str(tmp_path / 'run')!r}), 1); "
            "print('rerun' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO / "tests",
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == "False"


def test_evaluation_records_episodes_or_fails_clearly(tmp_path):
    run = run_in_process(tmp_path / "run", 1)
    result = run_module("crllk.evaluate", f"run={run}", "episodes=2", "num_envs=2",
                        "record=true", "record_episodes=2")
    assert result.returncode == 0, result.stderr
    path = run / "recordings" / "eval.rrd"
    assert f"recording: {path} (2 episodes, 24 steps)" in result.stdout
    assert sum(batch.num_rows for batch in read_recording(path)[ROBOT]) == 24
    shutil.rmtree(path.parent)  # the recording and its lock file
    path.parent.write_text("not a folder")
    result = run_module("crllk.evaluate", f"run={run}", "episodes=1", "record=true")
    assert result.returncode == 2
    assert result.stderr.startswith("error:") and "cannot write the recording" in result.stderr
    assert "Traceback" not in result.stderr
    assert result.stdout == ""  # refused before playing an episode
