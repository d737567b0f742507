"""What the project's servers and Ray listen on: this machine's loopback interface only."""

from __future__ import annotations

import ipaddress
import os
import re
from collections.abc import Sequence

LOOPBACK = "127.0.0.1"
"""The address every server the project starts binds (live viewers, Ray, the docs)."""
RAY_LOCAL_ONLY = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}
"""Without it Ray on Linux replaces 127.0.0.1 by the machine's address and listens on every
interface."""
RAY_LAUNCHER = "hydra/launcher=ray_local"
"""The project's Hydra launcher choice that starts (or joins) Ray for a sweep."""
_RAY_LAUNCHER_CHOICE = re.compile(r"^\+{0,2}hydra/launcher=.*ray")
"""Any launcher choice of Ray: the project's, or the plugin's own (``hydra/launcher=ray``)."""


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine's loopback interface."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def keep_ray_launcher_local(argv: Sequence[str]) -> bool:
    """For a sweep on a Ray launcher (:data:`RAY_LAUNCHER`, or the plugin's own ``ray``): sets
    :data:`RAY_LOCAL_ONLY` in this process's environment before Ray is imported, unless the
    user set the variable (a user who exports ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=1`` asks for
    every interface). Returns whether it did."""
    if not any(_RAY_LAUNCHER_CHOICE.match(argument) for argument in argv):
        return False
    changed = False
    for key, value in RAY_LOCAL_ONLY.items():
        if key not in os.environ:
            os.environ[key] = value
            changed = True
    return changed
