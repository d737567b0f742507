"""The tutorials of the documentation site work as written: every file a tutorial shows is
written into a copy of the source tree, every command of its ``bash`` blocks runs there at a
tiny budget, and every command of its ``console`` blocks (a robot, an installation) exists."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
TUTORIALS = REPO / "docs" / "tutorials"
BLOCK = re.compile(r'^```(\w+)(?: title="([^"]+)")?\n(.*?)^```$', re.MULTILINE | re.DOTALL)

TINY = {
    "crllk.train": {"num_envs": "2", "rollout_steps": "8", "ppo.minibatch_size": "8",
                    "ppo.epochs": "2", "total_frames": "32", "progress": "false",
                    "eval.episodes": "4", "eval.num_envs": "2", "workers": "1"},
    "crllk.evaluate": {"episodes": "4", "num_envs": "2"},
}
"""Each command's budget, replacing the tutorial's value of the same setting or added."""
TINY_OPTIONS = {"crllk.pictures": ["--steps", "30"], "crllk.deploy --parity": ["--parity-frames",
                                                                               "20"]}
"""Options added to a command (the tutorials leave these at their defaults)."""


def blocks(page: Path) -> list[tuple[str, str | None, str]]:
    """The fenced code blocks of a page: (language, title, body)."""
    return BLOCK.findall(page.read_text())


def tiny(command: str) -> str:
    """A ``python -m crllk.<command> ...`` line at a tiny budget."""
    words = shlex.split(command)
    module = words[2] if words[:2] == ["python", "-m"] else None
    settings = TINY.get(module or "", {})
    kept = [w for w in words if w.split("=", 1)[0] not in settings]
    kept += [f"{key}={value}" for key, value in settings.items()]
    for prefix, extra in TINY_OPTIONS.items():
        if command.startswith(f"python -m {prefix}"):
            kept += extra
    return shlex.join(kept)


def script(body: str) -> str:
    """A ``bash`` block with its continuation lines joined and its commands made tiny (a
    here-document's lines are left alone)."""
    lines, out, heredoc = body.replace("\\\n", " ").splitlines(), [], None
    for line in lines:
        if heredoc:
            out.append(line)
            heredoc = None if line.strip() == heredoc else heredoc
            continue
        match = re.search(r"<<'(\w+)'", line)
        if match:
            heredoc = match.group(1)
            out.append(line)
        elif line.startswith("python -m crllk."):
            out.append(tiny(line.split("  #")[0]))
        else:
            out.append(line)
    return "\n".join(out)


@pytest.fixture
def sandbox(tmp_path):
    """A copy of the package, its assets and tasks, where ``python`` is this interpreter."""
    root = tmp_path / "checkout"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for part in ("crllk", "assets", "tasks"):
        shutil.copytree(REPO / part, root / part, ignore=ignore)
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "python").write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    (bin_dir / "python").chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
           "PYTHONPATH": str(root), "CRLLK_DEBUG": "1"}
    return root, env


def follow(page: Path, root: Path, env: dict[str, str]) -> str:
    """Does what the page says, in order; returns what its commands printed."""
    printed = []
    for language, title, body in blocks(page):
        if title:
            target = root / title
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(body)
        elif language == "bash":
            done = subprocess.run(["bash", "-euo", "pipefail", "-c", script(body)], cwd=root,
                                  env=env, capture_output=True, text=True, timeout=900)
            assert done.returncode == 0, \
                f"{page.name}:\n{script(body)}\n{done.stdout}\n{done.stderr}"
            printed.append(done.stdout)
        elif language == "console":
            for line in body.splitlines():
                if line.startswith("python -m "):
                    module = line.split()[2]
                    done = subprocess.run([sys.executable, "-m", module, "--help"], cwd=root,
                                          env=env, capture_output=True, text=True, timeout=120)
                    assert done.returncode == 0, f"{page.name}: {module}: {done.stderr}"
    return "".join(printed)


def test_every_tutorial_is_tested():
    pages = {p.name for p in TUTORIALS.glob("*.md")} - {"index.md"}
    assert pages == {"add-a-map.md", "add-a-constraint.md", "add-an-algorithm.md", "deploy.md"}


def test_the_tiny_budget_replaces_the_tutorial_s():
    line = tiny("python -m crllk.evaluate run=runs/x episodes=100")
    assert line == "python -m crllk.evaluate run=runs/x episodes=4 num_envs=2"


def test_add_a_map(sandbox):
    root, env = sandbox
    printed = follow(TUTORIALS / "add-a-map.md", root, env)
    assert "on the road: True" in printed
    assert (root / "outputs/long_loop").is_dir() and any((root / "outputs/long_loop").iterdir())
    assert (root / "runs/long_loop-state/eval.json").is_file()


def test_add_a_constraint(sandbox):
    root, env = sandbox
    printed = follow(TUTORIALS / "add-a-constraint.md", root, env)
    assert "J_crate" in printed
    assert "lambda_crossing" in (root / "runs/crossing/metrics.csv").read_text().splitlines()[0]
    # the places a new signal goes are where the page says
    assert "SIGNALS = {" in (REPO / "crllk/tasks/constraints.py").read_text()
    lane_keeping = (REPO / "crllk/tasks/lane_keeping.py").read_text()
    assert "signals = {" in lane_keeping and '"lane_crossing":' in lane_keeping
    assert "def test_lane_crossing_probes" in (REPO / "tests/test_tasks.py").read_text()


def test_add_an_algorithm(sandbox):
    root, env = sandbox
    follow(TUTORIALS / "add-an-algorithm.md", root, env)
    header = (root / "runs/kl/metrics.csv").read_text().splitlines()[0].split(",")
    assert "epochs" in header
    assert (root / "runs/kl/eval.json").is_file()


def test_deploy_on_a_duckiebot(sandbox):
    root, env = sandbox
    printed = follow(TUTORIALS / "deploy.md", root, env)
    assert "last command: left" in printed
    assert (root / "runs/robot/policy.onnx").is_file()
    rows = (root / "outputs/commands.csv").read_text().splitlines()
    assert len(rows) == 31
