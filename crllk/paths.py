"""Where the project's shipped files live, resolved from the package, never the working
directory: ``assets/mjcf`` and ``tasks`` at the top of the source tree, or their copies inside
an installed wheel (``crllk/shipped``, made by ``setup.py`` when the wheel is built)."""

from __future__ import annotations

from pathlib import Path

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


def task_file(name: str) -> Path:
    """Path of the shipped task YAML called ``name`` (the top-level ``tasks/`` folder)."""
    return TASKS_DIR / f"{name}.yaml"


def task_names() -> list[str]:
    """Names of all shipped tasks."""
    return sorted(p.stem for p in TASKS_DIR.glob("*.yaml"))
