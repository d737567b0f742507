"""A built wheel carries the robot and the tasks: installed elsewhere, crllk loads every task
from any directory, and runs go under the current directory."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import crllk
from crllk.config import validate
from crllk.training.compose import compose_config

REPO = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "crllk", "assets", "tasks")


def test_an_installed_wheel_loads_every_task_from_any_directory(tmp_path):
    source = tmp_path / "source"
    for name in SOURCES:  # a copy, so that building leaves the checkout clean
        if (REPO / name).is_dir():
            shutil.copytree(REPO / name, source / name,
                            ignore=shutil.ignore_patterns("__pycache__", "shipped"))
        else:
            source.mkdir(exist_ok=True)
            shutil.copy2(REPO / name, source / name)
    wheels, site = tmp_path / "wheels", tmp_path / "site"
    _pip("wheel", "--no-deps", "--no-build-isolation", "-w", str(wheels), str(source))
    _pip("install", "--no-deps", "--target", str(site), str(next(wheels.glob("crllk-*.whl"))))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    probe = ("import crllk, sys; from crllk.paths import task_names; "
             f"assert crllk.__file__.startswith({str(site)!r}), crllk.__file__; "
             "names = task_names(); assert {'small_loop', 'zigzag', 'obstacle_loop'} <= "
             "set(names), names; env = crllk.load('obstacle_loop', observation='pixels'); "
             "print(env.reset().observation['pixels'].shape)")
    done = subprocess.run([sys.executable, "-c", probe], cwd=elsewhere, capture_output=True,
                          text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(site)})
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "(30, 40, 3)"


def test_default_run_directories_go_under_the_current_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = validate(compose_config(["task=zigzag"]))
    assert config.resolved_run_dir() == tmp_path / "runs" / "zigzag" / \
        "crllk-discrete-pixels-seed0"
    assert not str(config.resolved_run_dir()).startswith(str(Path(crllk.__file__).parent))


def _pip(*args: str) -> None:
    done = subprocess.run([sys.executable, "-m", "pip", "-q", *args], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
