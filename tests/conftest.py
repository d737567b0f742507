"""Test configuration: headless rendering is chosen before any test module imports mujoco."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from filelock import FileLock

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])


TINY_EXPERIMENT = ["--frames", "16", "--seeds", "0", "--episodes", "2", "--jobs", "1",
                   "--set", "num_envs=2", "workers=1",
                   "rollout_steps=8", "ppo.minibatch_size=8", "ppo.epochs=1", "task.horizon=12",
                   "eval.every=1", "eval.episodes=2", "eval.num_envs=10"]
"""``python -m crllk.experiments`` settings small enough for a test: one 16-frame run per agent,
one at a time in the experiment's own processes (no worker to start: the other core runs other
tests). Its runs make their final evaluation with ``crllk.evaluate``'s settings (episodes, seed
and ten simulations), so the experiment reuses it and evaluates only their mode."""


@pytest.fixture(scope="session")
def tiny_experiments(tmp_path_factory):
    """Runs ``python -m crllk.experiments all`` at the tiny budget, once per test session;
    returns (runs, results, its stdout).

    Under pytest-xdist (``make test`` runs one worker per core) every worker has its own session
    fixtures, so the first worker to ask trains the runs in the directory the workers share, under
    a file lock, and the others wait for it and read them."""
    shared = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        shared = shared.parent  # this session's directory, above the workers' own
    root = shared / "experiments"
    runs, results, stdout = root / "runs", root / "results", root / "stdout.txt"
    with FileLock(f"{root}.lock"):
        if not stdout.exists():
            completed = subprocess.run(
                [sys.executable, "-m", "crllk.experiments", "all", *TINY_EXPERIMENT,
                 "--runs-root", str(runs), "--results", str(results)],
                cwd=Path(__file__).resolve().parents[1], capture_output=True, text=True,
                timeout=600)
            assert completed.returncode == 0, \
                completed.stdout[-3000:] + completed.stderr[-3000:]
            stdout.write_text(completed.stdout)
    return runs / "pixels", results / "pixels", stdout.read_text()


@pytest.fixture
def load_task():
    """``crllk.load`` with its keyword arguments; the renderers of every environment built are
    released after the test."""
    import crllk

    built = []

    def make(task, **kwargs):
        env = crllk.load(task, **kwargs)
        built.append(env)
        return env

    yield make
    for env in built:
        env.physics.free_renderers()
