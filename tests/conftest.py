"""Test configuration: headless rendering is chosen before any test module imports mujoco."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])


TINY_EXPERIMENT = ["--frames", "16", "--seeds", "0", "--episodes", "2", "--set", "num_envs=2",
                   "rollout_steps=8", "ppo.minibatch_size=8", "ppo.epochs=1", "task.horizon=12",
                   "eval.every=1", "eval.episodes=2", "eval.num_envs=2"]
"""``python -m crllk.experiments`` settings small enough for a test: one 16-frame run per agent."""


@pytest.fixture(scope="session")
def tiny_experiments(tmp_path_factory):
    """Runs ``python -m crllk.experiments all`` at the tiny budget; returns (runs, results)."""
    root = tmp_path_factory.mktemp("experiments")
    runs, results = root / "runs", root / "results"
    completed = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "all", *TINY_EXPERIMENT, "--runs-root",
         str(runs), "--results", str(results)], cwd=Path(__file__).resolve().parents[1],
        capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr[-3000:]
    return runs / "pixels", results / "pixels", completed.stdout


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist reads the groups
def pytest_collection_modifyitems(items):
    """Under pytest-xdist (``make test`` runs ``-n auto --dist loadgroup``), the tests that read
    :func:`tiny_experiments` share one worker, so its runs are trained once, not once per
    worker."""
    for item in items:
        if "tiny_experiments" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.xdist_group("tiny_experiments"))
