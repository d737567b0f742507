"""Where the project's files live, resolved from the package, never the working directory."""

from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_ROOT = PACKAGE_DIR.parent
ASSETS_DIR = REPO_ROOT / "assets" / "mjcf"
TASKS_DIR = REPO_ROOT / "tasks"
DUCKIEBOT_XML = ASSETS_DIR / "duckiebot.xml"


def task_file(name: str) -> Path:
    """Path of the task YAML called ``name`` in the top-level ``tasks/`` folder."""
    return TASKS_DIR / f"{name}.yaml"


def task_names() -> list[str]:
    """Names of all tasks shipped in ``tasks/``."""
    return sorted(p.stem for p in TASKS_DIR.glob("*.yaml"))
