"""A run's directory: one trainer at a time."""

from __future__ import annotations

import fcntl
import io
from pathlib import Path

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.errors import ConfigError

SOURCE_RUN = "run"
"""How errors about the run directory name their source."""
EVAL_RECORDING = Path("recordings") / "eval.rrd"
"""Where ``python -m crllk.evaluate record=true`` records a run's episodes, in its directory."""


def lock_run_dir(run_dir: Path) -> io.TextIOWrapper:
    """Holds ``run_dir/.lock`` exclusively until the returned file is closed (or the process
    ends, even by a kill), so two processes never train one run.

    Raises:
        ConfigError: if another process holds the lock.
    """
    if run_dir.exists() and not run_dir.is_dir():
        raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir} is a file, not a directory")
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        handle = (run_dir / ".lock").open("w")
    except OSError as err:
        raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir}: cannot create or write the run "
                          f"directory: {err.strerror or err}") from None
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir} is being trained by another "
                          "process; wait for it to finish or choose another run_dir") from None
    return handle
