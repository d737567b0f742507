"""Atomic files: a checkpoint or table is either the old complete file or the new complete one.

Writing goes to a temporary file in the same folder, which is flushed to disk and then renamed
over the target (``os.replace`` is atomic on POSIX), so a run killed at any moment leaves no
half-written checkpoint behind.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import torch

CHECKPOINT_FORMAT = 1
"""Version of the checkpoint layout written by :mod:`crllk.train`."""


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


def save_checkpoint(path: str | Path, state: dict[str, Any]) -> Path:
    """Saves ``state`` with ``torch.save`` atomically, stamped with the format version."""
    return atomic_write(path, lambda handle: torch.save(
        {"format": CHECKPOINT_FORMAT, **state}, handle))


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Loads a checkpoint written by :func:`save_checkpoint`."""
    path = Path(path)
    state = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{path}: not a crllk checkpoint of format {CHECKPOINT_FORMAT}")
    return state


__all__ = ["CHECKPOINT_FORMAT", "atomic_write", "atomic_write_text", "load_checkpoint",
           "save_checkpoint"]
