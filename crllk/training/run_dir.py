"""A run's directory and who may write in it at the same time.

Locks (``flock``, released when their holder ends, even by a kill; their files are created
without following a link and never truncated):

- ``<run>/.lock``: the trainer's, held for the whole run, so two processes never train one
  run; a second trainer is refused with one line.
- ``.<file>.lock`` beside each file that ``python -m crllk.evaluate``, ``python -m
  crllk.export`` and ``python -m crllk.record`` write (``eval.json`` or ``<name>.json``,
  ``recordings/eval.rrd``, ``policy.onnx``; :func:`crllk.files.output_lock`), held from
  before the policy is loaded until the file is written, and by the trainer while it writes
  its final ``eval.json``. Two commands writing the same file run one after the other (the
  second says so and waits), so each writes the result of the policy it loaded, the later
  one last, and nothing is torn or lost.

Evaluating or exporting does not take the trainer's lock: a run can be evaluated while it
trains (its checkpoints and ``policy.pt`` are replaced atomically, so a reader sees a whole
one), and evaluations of one run under different names (the robustness conditions) run side
by side.
"""

from __future__ import annotations

from pathlib import Path
from typing import IO

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.errors import ConfigError
from crllk.files import WriteError, lock_file

SOURCE_RUN = "run"
"""How errors about the run directory name their source."""
RUN_LOCK = ".lock"
"""The trainer's lock file in a run directory."""
EVAL_RECORDING = Path("recordings") / "eval.rrd"
"""Where ``python -m crllk.evaluate record=true`` records a run's episodes, in its directory."""
EVAL_FILE = "eval.json"
"""``python -m crllk.evaluate``'s result in a run directory."""
FLEET_FILE = "fleet"
"""The name (without ``.json``) of a fleet evaluation's result in a run directory."""
RUN_FOLDERS = ("checkpoints", "recordings")
"""The folders the commands write in inside a run directory."""


def check_run_folders(run_dir: Path) -> None:
    """Refuses a run directory whose :data:`RUN_FOLDERS` are symbolic links: the commands
    write there, and a link planted in a shared run would send their files elsewhere.

    Raises:
        ConfigError: naming the folder.
    """
    for name in RUN_FOLDERS:
        folder = Path(run_dir) / name
        if folder.is_symlink():
            raise ConfigError(folder, "<folder>", "is a symbolic link, which is not followed "
                              "(remove it)")


def lock_run_dir(run_dir: Path) -> IO[bytes]:
    """Holds ``run_dir/.lock`` exclusively until the returned file is closed (or the process
    ends, even by a kill), so two processes never train one run.

    Raises:
        ConfigError: if another process holds the lock, or the directory or its lock file
            cannot be used (a symbolic link planted as ``.lock`` is refused, not followed).
    """
    if run_dir.exists() and not run_dir.is_dir():
        raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir} is a file, not a directory")
    check_run_folders(run_dir)
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        return lock_file(run_dir / RUN_LOCK, wait=False)
    except BlockingIOError:
        raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir} is being trained by another "
                          "process; wait for it to finish or choose another run_dir") from None
    except WriteError as err:
        raise ConfigError(SOURCE_RUN, "run_dir", f"{err.filename}: {err.strerror}") from None
    except OSError as err:
        raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir}: cannot create or write the run "
                          f"directory: {err.strerror or err}") from None
