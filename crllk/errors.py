"""Errors for bad input: each names the file, the field and what is wrong."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path


class ConfigError(ValueError):
    """A task, map or override that cannot be used.

    The message always reads ``<source>: <field>: <problem>`` so that a user can find the
    offending line without a traceback.
    """

    def __init__(self, source: str | Path | None, field: str, problem: str) -> None:
        self.source = str(source) if source is not None else "<input>"
        self.field = field
        self.problem = problem
        super().__init__(f"{self.source}: {field}: {problem}")


class MapError(ConfigError):
    """A Duckietown map description that cannot be built."""


class MapWarning(UserWarning):
    """Part of a map description that is read and ignored: ``<source>: <field>: <what>``."""

    def __init__(self, source: str | Path, field: str, problem: str) -> None:
        self.source, self.field, self.problem = str(source), field, problem
        super().__init__(f"{self.source}: {field}: {problem}")


def show_map_warnings_on_one_line() -> None:
    """Prints each :class:`MapWarning` as one line, ``warning: <source>: <field>: <what>``,
    without the source line Python adds; other warnings are shown as before."""
    shown = warnings.showwarning
    if getattr(shown, "one_line_map_warnings", False):
        return

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if issubclass(category, MapWarning):
            print(f"warning: {message}", file=sys.stderr if file is None else file)
        else:
            shown(message, category, filename, lineno, file, line)

    show.one_line_map_warnings = True  # type: ignore[attr-defined]
    warnings.showwarning = show


class RecordingError(ConfigError):
    """A recording that cannot be written: ``<path>: cannot write the recording: <reason>``."""

    def __init__(self, path: str | Path, reason: str) -> None:
        self.path = str(path)
        self.reason = reason
        super().__init__(path, "cannot write the recording", reason)
