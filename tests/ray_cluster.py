"""A Ray head on 127.0.0.1 for the slow tests of the Ray launcher and the Ray collector, and the
addresses a process tree listens on."""

from __future__ import annotations

import os
import secrets
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import psutil

from crllk.network import RAY_LOCAL_ONLY

LOOPBACK = {"127.0.0.1", "::ffff:127.0.0.1", "::1"}
"""The addresses of this machine's loopback interface, as ``psutil`` reports them."""
HEAD_START_S = 180
"""The longest a head may take to start on a loaded machine (s)."""
HEAD_STOP_S = 60
"""The longest a head may take to stop on SIGTERM before it is killed (s)."""


def free_port() -> int:
    """A TCP port nothing listens on at the moment, on 127.0.0.1."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def listening(roots: list[int]) -> set[tuple[str, int]]:
    """The TCP addresses the processes ``roots`` and their descendants listen on."""
    pids = set()
    for root in roots:
        try:
            process = psutil.Process(root)
            pids |= {root, *(child.pid for child in process.children(recursive=True))}
        except psutil.NoSuchProcess:
            continue
    return {(c.laddr.ip, c.laddr.port) for c in psutil.net_connections(kind="tcp")
            if c.status == psutil.CONN_LISTEN and c.pid in pids}


@contextmanager
def ray_head(log: Path) -> Iterator[tuple[str, dict[str, str], subprocess.Popen]]:
    """A Ray head bound to 127.0.0.1 on a free port with 2 CPUs and its own token (nothing
    written to ~/.ray), its output in ``log``; yields its address, the environment that
    reaches it and its process; stopped by its own pid (``ray start --block`` stops its
    processes on SIGTERM)."""
    port = free_port()
    env = {**os.environ, **RAY_LOCAL_ONLY, "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN": secrets.token_hex(32), "RAY_USAGE_STATS_ENABLED": "0"}
    with log.open("w") as out:
        head = subprocess.Popen(
            [str(Path(sys.executable).with_name("ray")), "start", "--head", "--block",
             "--node-ip-address", "127.0.0.1", "--port", str(port),
             "--ray-client-server-port", str(free_port()), "--include-dashboard=false",
             "--num-cpus", "2", "--disable-usage-stats"],
            env=env, stdout=out, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + HEAD_START_S
        while "Ray runtime started" not in log.read_text():
            assert head.poll() is None and time.monotonic() < deadline, log.read_text()[-3000:]
            time.sleep(0.5)
        yield f"127.0.0.1:{port}", env, head
    finally:
        head.terminate()
        try:
            head.wait(timeout=HEAD_STOP_S)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait()
