"""The native rerun viewer as a process: probe the viewer port, start ``rerun`` on it.

Viewers listen on ``VIEWER_HOST`` (127.0.0.1) only. :func:`spawn_viewer` reuses a viewer
already answering on the port or runs the ``rerun`` executable (``rerun --bind 127.0.0.1``)
and waits until it listens; :func:`start_viewer` runs one with extra arguments (a viewer that
connects to a training run, a headless one) and :func:`stop_viewer` ends it with its process
group. This module does not import the rerun Python package: it runs the executable with
:mod:`subprocess` and probes sockets; :mod:`crllk.recording.sinks`,
:mod:`crllk.recording.live` and :mod:`crllk.recording.headless` talk to the viewer.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

VIEWER_HOST = "127.0.0.1"
"""Spawned and served viewers listen on this address only."""
VIEWER_PORT = 9876
"""gRPC port of a spawned or served viewer."""
_SPAWN_TIMEOUT = 15.0
"""How long a spawned viewer may take to listen (s)."""
_STOP_TIMEOUT = 5.0
"""How long a viewer may take to exit after SIGTERM before it is killed (s)."""
_PROBE_TIMEOUT = 1.0
"""How long a listener on the viewer port may take to answer an HTTP/2 preface (s)."""
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
"""The HTTP/2 client preface and an empty SETTINGS frame; gRPC servers answer with theirs."""
_HTTP2_SETTINGS = 4
"""Frame type of an HTTP/2 SETTINGS frame (byte 3 of the frame header)."""
_SPAWN_GRACE = 1.0
"""A spawned viewer must still run this long after it listens (s); one without a display
listens first and exits right after."""
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
"""Terminal colour codes in the viewer's log."""


def _port_state(port: int) -> str:
    """``"free"``, ``"grpc"`` (an HTTP/2 server, such as a rerun viewer, answers on
    ``VIEWER_HOST:port``) or ``"other"`` (something listens and does not answer: a rerun
    stream connected to it would hang when closed)."""
    try:
        with socket.create_connection((VIEWER_HOST, port), timeout=_PROBE_TIMEOUT) as probe:
            probe.sendall(_HTTP2_PREFACE)
            frame = probe.recv(9)
    except ConnectionRefusedError:
        return "free"
    except OSError:
        return "other"
    return "grpc" if len(frame) == 9 and frame[3] == _HTTP2_SETTINGS else "other"


def viewer_listening(port: int = VIEWER_PORT) -> bool:
    """Whether a gRPC server, such as a rerun viewer, answers on ``VIEWER_HOST:port``."""
    return _port_state(port) == "grpc"


def check_port_free(port: int) -> None:
    """Raise OSError when ``VIEWER_HOST:port`` cannot be bound (taken)."""
    with socket.socket() as probe:
        probe.bind((VIEWER_HOST, port))


def _viewer_executable() -> str | None:
    """The ``rerun`` viewer: on PATH, else beside the running Python (an unactivated venv)."""
    found = shutil.which("rerun")
    if found:
        return found
    beside = Path(sys.executable).parent / "rerun"
    return str(beside) if beside.is_file() and os.access(beside, os.X_OK) else None


def free_port() -> int:
    """A TCP port of ``VIEWER_HOST`` that is free now (chosen by the system)."""
    with socket.socket() as probe:
        probe.bind((VIEWER_HOST, 0))
        return probe.getsockname()[1]


def spawn_viewer(port: int = VIEWER_PORT) -> str:
    """Start a native viewer listening on ``127.0.0.1:port`` (or reuse one already there) and
    return its gRPC URL.

    Raises:
        RuntimeError: with the reason when no viewer runs (no executable, no display, ...).
    """
    url = f"rerun+http://{VIEWER_HOST}:{port}/proxy"
    state = _port_state(port)
    if state == "grpc":
        return url
    if state == "other":
        raise RuntimeError(f"{VIEWER_HOST}:{port} is taken by something that is not a viewer")
    start_viewer(port)
    return url


def has_display() -> bool:
    """Whether a window can be opened: always off Linux; on Linux, an X11 or Wayland display
    is named in the environment (without one a viewer listens first and exits right after,
    which can take longer than :data:`_SPAWN_GRACE` on a busy machine)."""
    return not sys.platform.startswith("linux") or any(
        os.environ.get(name) for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"))


def start_viewer(port: int, *args: str, timeout: float = _SPAWN_TIMEOUT) -> subprocess.Popen:
    """Run ``rerun --bind 127.0.0.1 --port <port> <args>`` in a session of its own and wait
    until it listens on the port; the viewer outlives this process unless stopped with
    :func:`stop_viewer`.

    Raises:
        RuntimeError: with the reason when it does not listen within ``timeout`` (s) or exits
            (no executable, no display, no Vulkan driver, port taken, ...).
    """
    executable = _viewer_executable()
    if executable is None:
        raise RuntimeError(f"no `rerun` executable on PATH or in {Path(sys.executable).parent}")
    if "--headless" not in args and not has_display():
        raise RuntimeError("the viewer cannot open a window: no display (DISPLAY and "
                           "WAYLAND_DISPLAY are unset)")
    with tempfile.TemporaryFile() as log:
        process = subprocess.Popen(
            [executable, "--bind", VIEWER_HOST, "--port", str(port), *args],
            stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
            env={**os.environ, "RERUN_APP_ONLY": "true"})
        if _wait_listening(process, port, timeout) and _still_running(process, _SPAWN_GRACE):
            return process
        stop_viewer(process)
        log.seek(0)
        reason = _last_error_line(log.read().decode(errors="replace"))
    raise RuntimeError(f"the viewer `{executable}` did not start: {reason}")


def stop_viewer(process: subprocess.Popen, timeout: float = _STOP_TIMEOUT) -> None:
    """End a viewer started here with its process group (``rerun`` on PATH may be a Python
    launcher whose child, the viewer binary, would outlive it): SIGTERM, then SIGKILL after
    ``timeout`` (s)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):  # the whole group has exited
            os.killpg(process.pid, sig)  # its own session: group id = pid
        try:
            process.wait(timeout=timeout)
            return
        except subprocess.TimeoutExpired:
            continue
    process.wait()


def _wait_listening(process: subprocess.Popen, port: int, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and process.poll() is None:
        if _port_state(port) == "grpc":
            return True
        time.sleep(0.1)
    return False


def _still_running(process: subprocess.Popen, seconds: float) -> bool:
    try:
        process.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        return True
    return False


def _last_error_line(text: str) -> str:
    """The most telling line of a viewer's log: its last error, colour codes removed."""
    lines = [line.strip() for line in _ANSI.sub("", text).splitlines() if line.strip()]
    errors = [line for line in lines if "error" in line.lower() or "panicked" in line]
    return (errors or lines or ["it exited without a message"])[-1]


__all__ = ["VIEWER_HOST", "VIEWER_PORT", "check_port_free", "free_port", "spawn_viewer",
           "start_viewer", "stop_viewer", "viewer_listening"]
