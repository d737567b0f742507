"""The pages of the documentation site as a reader sees their text: a page of ``docs/`` with
the committed files it includes (``docs/hooks/includes.py``), so a check of a quoted figure
reads the same text the site shows."""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"


@cache
def _hook():
    spec = importlib.util.spec_from_file_location("crllk_docs_includes",
                                                  DOCS / "hooks" / "includes.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def page(name: str) -> str:
    """The Markdown of ``docs/<name>`` with its includes done (``README.md`` as it is)."""
    if name == "README.md":
        return (REPO / name).read_text()
    return _hook().expand((DOCS / name).read_text(), name)


def prose(name: str) -> str:
    """:func:`page` with its whitespace collapsed, so a quote may wrap anywhere."""
    return " ".join(page(name).split())


def pages() -> list[str]:
    """Every page of the site, as paths under ``docs/``."""
    return sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md"))
