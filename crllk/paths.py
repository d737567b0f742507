"""Where the project's shipped files live, resolved from the package, never the working
directory: ``assets/mjcf`` and ``tasks`` at the top of the source tree, or their copies inside
an installed wheel (``crllk/shipped``, made by ``setup.py`` when the wheel is built)."""

from __future__ import annotations

import re
from pathlib import Path

from crllk.errors import ConfigError

PACKAGE_DIR = Path(__file__).resolve().parent
SHIPPED_DIR = PACKAGE_DIR / "shipped"
"""The copies of ``assets/mjcf`` and ``tasks`` inside an installed wheel."""
SOURCE_ROOT = PACKAGE_DIR.parent
"""The top of the source tree (a checkout or an editable install)."""


def _shipped(relative: str) -> Path:
    installed = SHIPPED_DIR / relative
    return installed if installed.is_dir() else SOURCE_ROOT / relative


ASSETS_DIR = _shipped("assets/mjcf")
TASKS_DIR = _shipped("tasks")
DUCKIEBOT_XML = ASSETS_DIR / "duckiebot.xml"
_TASK_NAME = re.compile(r"[A-Za-z0-9_](?:[A-Za-z0-9_-]|\.(?!\.))*")


def task_file(name: str) -> Path:
    """Path of the shipped task YAML called ``name`` (the top-level ``tasks/`` folder).

    Raises:
        ConfigError: if ``name`` is not a plain name (a task name read from a shared run's
            ``config.yaml`` such as ``../../x`` never leaves ``tasks/``).
    """
    problem = task_name_problem(name)
    if problem:
        raise ConfigError(name, "task", f"{problem}; give a task or map file by its path ending "
                          "in .yaml")
    return TASKS_DIR / f"{name}.yaml"


def task_name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a task, or None. A task's name becomes part of file and folder
    names (a run's folder, an exported scene), so it is a plain name: no ``/``, no ``..``."""
    if _TASK_NAME.fullmatch(name):
        return None
    return f"not a task name: {name!r} (letters, digits, '_', '-' and single dots)"


def task_names() -> list[str]:
    """Names of all shipped tasks."""
    return sorted(p.stem for p in TASKS_DIR.glob("*.yaml"))
