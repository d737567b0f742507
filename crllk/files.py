"""Reading CSV logs, and writing files safely in folders others may write in too.

Atomic files: a checkpoint or table is either the old complete file or the new complete one.
Writing goes to a temporary file in the same folder, created new (``O_EXCL``) and named after
the target and the writer's process id (``.<name>.<pid>-<random>.tmp``), which is flushed to
disk and then renamed over the target (``os.replace`` is atomic on POSIX, and replaces a
symbolic link planted at the target instead of writing through it); the folder is synced
after the rename. A run killed at any moment leaves no half-written file behind, only a
temporary file, which is removed later once its writer is gone (:func:`remove_leftovers`),
never while its writer may still be at work.

Files written in place (the CSV logs, which grow a row at a time, and lock files) are opened
with ``O_NOFOLLOW``: a symbolic link planted at their path is refused, naming the file, instead
of being written through. A write that fails (a full disk, a read-only file system, no
permission) raises :class:`WriteError`: one line naming the file and the cause.
"""

from __future__ import annotations

import csv
import errno
import fcntl
import glob
import io
import os
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO

STALE_TEMP_AGE_S = 24 * 3600.0
"""A temporary file not modified for this long (s) is a leftover even where its writer cannot
be told (a file of another machine, or named without a process id): a writer at work modifies
its file far more often."""

_FILE_MODE = 0o666  # as open() creates files, before the umask
_TEMP_SUFFIX = ".tmp"
_TEMP_NAME = re.compile(r"\..+\.(?P<pid>\d+)-[^.]+\.tmp")
_LINK_ERRNOS = (errno.ELOOP, errno.EMLINK)  # what O_NOFOLLOW gives for a link (Linux, BSD)


class WriteError(OSError):
    """A file that cannot be written: ``<path>: <cause>`` on one line
    (:func:`crllk.cli.one_line`), naming the file meant, never a temporary one."""


# ----- opening without following links -------------------------------------------------------
def open_no_follow(path: str | Path, flags: int, mode: int = _FILE_MODE) -> int:
    """``os.open(path, flags | O_NOFOLLOW)``: a file descriptor of ``path`` itself.

    Raises:
        WriteError: if ``path`` is a symbolic link (it is not followed), or for any other
            failure (the file named, with the cause).
    """
    try:
        return os.open(path, flags | os.O_NOFOLLOW | os.O_CLOEXEC, mode)
    except OSError as err:
        if err.errno in _LINK_ERRNOS and os.path.islink(path):
            raise WriteError(err.errno, "is a symbolic link, which is not followed (remove it)",
                             str(path)) from None
        raise WriteError(err.errno, err.strerror, str(path)) from None


@contextmanager
def writing(path: str | Path) -> Iterator[None]:
    """Turns an OSError of the block (or torch's failed write) into a :class:`WriteError`
    naming ``path``."""
    try:
        yield
    except WriteError:
        raise
    except Exception as err:
        cause = _write_failure(err, Path(path))
        if cause is None:
            raise
        raise WriteError(*cause, str(path)) from err


def _write_failure(err: BaseException, path: Path) -> tuple[int, str] | None:
    """The errno and reason of a failed write: an OSError, or one behind an exception (torch's
    ``RuntimeError: [enforce fail at inline_container.cc...]`` keeps the OSError of the
    failed write as its context); None for an exception that is no failed write."""
    if isinstance(err, OSError):
        return (err.errno, err.strerror or str(err)) if err.errno is not None else None
    if not isinstance(err, RuntimeError):
        return None
    seen = err.__cause__ or err.__context__
    while seen is not None:
        if isinstance(seen, OSError) and seen.errno is not None:
            return seen.errno, seen.strerror or os.strerror(seen.errno)
        seen = seen.__cause__ or seen.__context__
    if "enforce fail" in str(err):
        with suppress(OSError):
            if shutil.disk_usage(_existing_folder(path)).free == 0:
                return errno.ENOSPC, os.strerror(errno.ENOSPC)
        return errno.EIO, f"the write failed ({str(err).splitlines()[0][:200]})"
    return None


# ----- atomic files --------------------------------------------------------------------------
def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _temp_prefix(path: Path) -> str:
    return f".{path.name}.{os.getpid()}-"


def sync_folder(folder: str | Path) -> None:
    """Flushes ``folder``'s entries to disk (a rename in it survives a power cut); a file
    system that cannot sync folders is left as it is."""
    with suppress(OSError):
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def atomic_write(path: str | Path, write: Callable[[IO[bytes]], object]) -> Path:
    """Calls ``write(file)`` on a new temporary file beside ``path``, then renames it to
    ``path``; then removes what killed writes of ``path`` left (:func:`remove_leftovers`).

    Raises:
        WriteError: naming ``path`` with the cause, when the file cannot be written (also
            when ``write`` fails for a full disk, as ``torch.save`` does).
    """
    path = Path(path)
    tmp: str | None = None
    try:
        with writing(path):
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=_TEMP_SUFFIX,
                                       dir=path.parent)
            os.chmod(tmp, _FILE_MODE & ~_umask())
            with os.fdopen(fd, "wb") as handle:
                write(handle)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise
    sync_folder(path.parent)
    remove_leftovers(path)
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Writes ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write(path, lambda handle: handle.write(text.encode("utf-8")))


@contextmanager
def atomic_output(path: str | Path) -> Iterator[Path]:
    """For a writer that opens its file by name (rerun's file sink): yields a path in a new
    private folder (mode 0700) beside ``path``, where no one else can plant a link, and renames
    the file written there to ``path`` when the block ends without an error. Either way the
    temporary folder goes.

    Raises:
        WriteError: naming ``path`` when the folder cannot be made or the file not renamed.
    """
    path = Path(path)
    with writing(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        folder = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=_TEMP_SUFFIX,
                                       dir=path.parent))
    try:
        yield folder / path.name
        with writing(path):
            os.chmod(folder / path.name, _FILE_MODE & ~_umask())
            os.replace(folder / path.name, path)
        sync_folder(path.parent)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    remove_leftovers(path)


def remove_leftovers(path: str | Path) -> list[Path]:
    """Removes the temporary files of writes of ``path`` that were killed before their rename
    (``.<name>.*.tmp`` beside it) and whose writer is gone (:func:`is_stale`); returns them.
    A write still at work in another process keeps its file."""
    path = Path(path)
    return _remove_stale(path.parent.glob(f".{glob.escape(path.name)}.*{_TEMP_SUFFIX}"))


def remove_stale_temp_files(folder: str | Path) -> list[Path]:
    """Removes every temporary file in ``folder`` (``.*.tmp``) whose writer is gone; returns
    them."""
    return _remove_stale(Path(folder).glob(f".*{_TEMP_SUFFIX}"))


def _remove_stale(candidates: Iterable[Path]) -> list[Path]:
    removed = []
    for leftover in sorted(candidates):
        if not is_stale(leftover):
            continue
        if leftover.is_dir() and not leftover.is_symlink():
            shutil.rmtree(leftover, ignore_errors=True)
        else:
            leftover.unlink(missing_ok=True)
        removed.append(leftover)
    return removed


def is_stale(temp: Path) -> bool:
    """Whether the temporary file (or folder) ``temp`` is a leftover: the process named in it
    is no longer running, or it was not modified for :data:`STALE_TEMP_AGE_S`."""
    try:
        modified = temp.lstat().st_mtime
    except FileNotFoundError:
        return False
    if time.time() - modified > STALE_TEMP_AGE_S:
        return True
    match = _TEMP_NAME.fullmatch(temp.name)
    return match is not None and not process_running(int(match["pid"]))


def process_running(pid: int) -> bool:
    """Whether a process ``pid`` runs on this machine (perhaps another user's)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, ValueError):
        return False
    return True


# ----- checks and locks ----------------------------------------------------------------------
def _existing_folder(path: Path) -> Path:
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def write_problem(path: str | Path) -> str | None:
    """Why a file could not be written at ``path`` (its folder created if needed), or None.
    The nearest existing folder is tried by creating (and removing) an empty file in it, so a
    read-only file system, missing permission or a special file system is found before any
    work, also for root."""
    path = Path(path)
    if path.is_dir():
        return f"{path} is a directory"
    folder = _existing_folder(path)
    if not folder.is_dir():
        return f"{folder} is a file, not a directory"
    try:
        fd, probe = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=_TEMP_SUFFIX, dir=folder)
    except OSError as err:
        return f"cannot write in {folder}: {err.strerror or err}"
    os.close(fd)
    os.unlink(probe)
    return None


def lock_file(path: str | Path, *, wait: bool) -> IO[bytes]:
    """Holds the lock file ``path`` (created if needed, never truncated, never through a link)
    exclusively until the returned file is closed or the process ends, even by a kill.

    Raises:
        BlockingIOError: without ``wait``, if another process holds it.
        WriteError: if it cannot be created or is a symbolic link.
    """
    fd = open_no_follow(path, os.O_RDWR | os.O_CREAT)
    handle = os.fdopen(fd, "r+b", buffering=0)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
    except BaseException:
        handle.close()
        raise
    return handle


def output_lock_path(path: str | Path) -> Path:
    """The lock file of writes of ``path``: ``.<name>.lock`` beside it."""
    path = Path(path)
    return path.parent / f".{path.name}.lock"


@contextmanager
def output_lock(path: str | Path) -> Iterator[None]:
    """Holds ``path``'s lock (:func:`output_lock_path`) while the block runs, so that commands
    writing the same file run one after the other: while another process holds it, this one
    says so on stderr and waits.

    Raises:
        WriteError: if the lock file cannot be created (or is a symbolic link).
    """
    path = Path(path)
    with writing(path):
        path.parent.mkdir(parents=True, exist_ok=True)
    lock = output_lock_path(path)
    try:
        handle = lock_file(lock, wait=False)
    except BlockingIOError:
        print(f"waiting for another process writing {path} to finish", file=sys.stderr,
              flush=True)
        handle = lock_file(lock, wait=True)
    try:
        yield
    finally:
        handle.close()


# ----- reading -------------------------------------------------------------------------------
def read_csv_rows(path: str | Path) -> tuple[list[str], list[dict[str, str]]]:
    """A CSV log's header and complete rows (``[], []`` if it does not exist), read without
    following a link. A row cut short by a kill while it was appended (the file does not end
    with a line end, or the row has fewer fields than the header) is left out.

    Raises:
        WriteError: if ``path`` is a symbolic link or cannot be read.
    """
    try:
        fd = open_no_follow(path, os.O_RDONLY)
    except WriteError as err:
        if err.errno == errno.ENOENT:
            return [], []
        raise
    with os.fdopen(fd, "rb") as handle:
        text = handle.read().decode("utf-8", errors="replace")
    complete = text[:text.rfind("\n") + 1]
    reader = csv.DictReader(io.StringIO(complete, newline=""))
    header = list(reader.fieldnames or [])
    rows = [row for row in reader if None not in row and None not in row.values()]
    return header, rows
