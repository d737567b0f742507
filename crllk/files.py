"""Reading YAML, and atomic files: a checkpoint or table is either the old complete file or
the new complete one.

Writing goes to a temporary file in the same folder, which is flushed to disk and then renamed
over the target (``os.replace`` is atomic on POSIX), so a run killed at any moment leaves no
half-written checkpoint behind.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO

import yaml

from crllk.errors import MapError

MAX_YAML_BYTES = 512 * 1024
"""Largest task or map file read (bytes), checked before parsing: 14 times the largest Duckietown
map file, and about 4 s of parsing."""

_FILE_MODE = 0o666  # as open() creates files, before the umask


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: str | Path, write: Callable[[IO[bytes]], None]) -> Path:
    """Calls ``write(file)`` on a temporary file beside ``path``, then renames it to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, _FILE_MODE & ~_umask())
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Writes ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write(path, lambda handle: handle.write(text.encode("utf-8")))


def read_yaml(path: Path) -> object:
    """Reads a YAML file, turning syntax errors into a :class:`MapError` naming the file.

    Raises:
        MapError: also for a file larger than :data:`MAX_YAML_BYTES`.
    """
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise MapError(path, "<file>", f"{size} bytes, more than the {MAX_YAML_BYTES} a task "
                           "or map file may have")
        return yaml.safe_load(path.read_text())
    except OSError as err:
        raise MapError(path, "<file>", f"cannot read: {err.strerror}") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else "<file>"
        raise MapError(path, where, f"not valid YAML: {getattr(err, 'problem', err)}") from None
