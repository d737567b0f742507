"""Where a recording goes: its file checked before the first step, the file and viewer sinks
opened, a failed final flush judged, and a written file read back.

Viewers listen on 127.0.0.1 only (:mod:`crllk.recording.viewer` runs and probes them). A viewer
that cannot be reached, or that goes away, is a warning: the file is written all the same. A
path that cannot be written raises :class:`~crllk.errors.RecordingError`.
"""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import rerun as rr
from rerun.chunk import RrdReader

from crllk.errors import RecordingError
from crllk.files import write_problem
from crllk.recording.viewer import (
    VIEWER_HOST,
    VIEWER_PORT,
    check_port_free,
    spawn_viewer,
    viewer_listening,
)

VIEWERS = ("none", "spawn", "serve")
FLUSH_TIMEOUT_S = 60.0
"""The longest the final flush may wait for its sinks (s): rerun's own default is unbounded,
and a sink that never answers must not hang a training run or a test."""
_FAILED_VIEWERS: set[str] = set()
"""Viewer modes that failed in this process and are not tried again (``"spawn"``)."""


def check_writable(path: str | Path) -> Path:
    """Create ``path``'s directory and check that a file can be written in it, so that a
    recording fails before stepping, not halfway. The file itself is left alone: it is written
    beside it and renamed over it at the end (:func:`crllk.files.atomic_output`), so a link
    planted at ``path`` is replaced, never written through.

    Raises:
        RecordingError: naming the path when the directory or the file cannot be created.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RecordingError(path, err.strerror or str(err)) from None
    problem = write_problem(path)
    if problem:
        raise RecordingError(path, problem)
    return path


def open_sinks(sink_path: Path | None, path: Path | None, viewer: str, problems: list[str]
               ) -> tuple[list, str | None]:
    """The sinks for ``sink_path`` (written as the file ``path``) and ``viewer``; an
    unreachable viewer becomes a warning.

    A viewer that could not be spawned is reported once per process: later recordings only
    reuse a viewer that answers by then (started by hand), and say nothing otherwise.
    """
    sinks: list = [rr.FileSink(sink_path)] if sink_path is not None else []
    url = None
    try:
        if viewer == "spawn":
            if "spawn" in _FAILED_VIEWERS and not viewer_listening(VIEWER_PORT):
                return sinks, None
            url = spawn_viewer(VIEWER_PORT)
            sinks.append(rr.GrpcSink(url))
        elif viewer == "serve":
            check_port_free(VIEWER_PORT)  # rerun's server would fail later, at the flush
            server = rr.GrpcServerSink(VIEWER_HOST, VIEWER_PORT)
            url = server.uri
            sinks.append(server)
    except Exception as err:  # any viewer failure must not stop the recording
        if viewer not in _FAILED_VIEWERS:
            problems.append(f"rerun viewer ({viewer}) unavailable, "
                            f"{'writing only ' + str(path) if path else 'nothing recorded'}: "
                            f"{err}")
        if viewer == "spawn":
            _FAILED_VIEWERS.add(viewer)
    return sinks, url


def flush_failed(problem: str, file: Path | None, viewer: str, problems: list[str]) -> None:
    """A failed final flush: the file's error without a viewer, else a lost viewer."""
    if viewer == "none" and file is not None:
        raise RecordingError(file, problem)
    problems.append(f"rerun viewer ({viewer}) lost while recording"
                    f"{', the file is complete' if file else ''}: {problem}")


def read_recording(path: str | Path) -> dict[str, list[pa.RecordBatch]]:
    """The record batches of the file's first recording, by entity path without the leading
    ``/`` (``rerun.chunk.RrdReader``; static rows have no time columns)."""
    chunks: dict[str, list[pa.RecordBatch]] = {}
    for chunk in RrdReader(path).stream():
        chunks.setdefault(chunk.entity_path.lstrip("/"), []).append(chunk.to_record_batch())
    return chunks


__all__ = ["FLUSH_TIMEOUT_S", "VIEWERS", "check_writable", "flush_failed", "open_sinks",
           "read_recording"]
