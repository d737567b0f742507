"""Reading YAML, and atomic files: a checkpoint or table is either the old complete file or
the new complete one.

Writing goes to a temporary file in the same folder, which is flushed to disk and then renamed
over the target (``os.replace`` is atomic on POSIX), so a run killed at any moment leaves no
half-written checkpoint behind.
"""

from __future__ import annotations

import glob
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


def atomic_write(path: str | Path, write: Callable[[IO[bytes]], object]) -> Path:
    """Calls ``write(file)`` on a temporary file beside ``path``, then renames it to ``path``;
    then removes what killed writes of ``path`` left (:func:`remove_leftovers`)."""
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
    remove_leftovers(path)
    return path


def remove_leftovers(path: str | Path) -> list[Path]:
    """Removes the temporary files of writes of ``path`` that were killed before their rename
    (``.<name>.*.tmp`` beside it) and returns them."""
    path = Path(path)
    leftovers = sorted(path.parent.glob(f".{glob.escape(path.name)}.*.tmp"))
    for leftover in leftovers:
        leftover.unlink(missing_ok=True)
    return leftovers


def write_problem(path: str | Path) -> str | None:
    """Why a file could not be written at ``path`` (its folder created if needed), or None."""
    path = Path(path)
    if path.is_dir():
        return f"{path} is a directory"
    folder = path.parent
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        return f"{folder} is a file, not a directory"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"cannot write in {folder}"
    return None


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Writes ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write(path, lambda handle: handle.write(text.encode("utf-8")))


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key that appears twice in one mapping."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark)
            if isinstance(key, str | int | float | bool | None):
                seen.add(key)
        return super().construct_mapping(node, deep)


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
        return yaml.load(path.read_text(encoding="utf-8"), Loader=_UniqueKeyLoader)
    except UnicodeDecodeError as err:
        raise MapError(path, "<file>", f"not a text file (UTF-8): byte {err.start} cannot be "
                       "decoded") from None
    except OSError as err:
        raise MapError(path, "<file>", f"cannot read: {err.strerror}") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else "<file>"
        raise MapError(path, where, f"not valid YAML: {getattr(err, 'problem', err)}") from None
