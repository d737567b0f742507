"""Errors for bad input: each names the file, the field and what is wrong."""

from __future__ import annotations

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


class RecordingError(ConfigError):
    """A recording that cannot be written: ``<path>: cannot write the recording: <reason>``."""

    def __init__(self, path: str | Path, reason: str) -> None:
        self.path = str(path)
        self.reason = reason
        super().__init__(path, "cannot write the recording", reason)
