"""``python -m crllk.export run=<run_dir> [out=<file>.onnx]``: a run's policy as ONNX.

Writes the deterministic policy (:mod:`crllk.deployment.export`): one camera image as uint8
30×40×3 RGB (pixel runs) or the state features (state runs) in, the two wheel duty cycles
out. Default ``out``: ``<run_dir>/policy.onnx``. Then ``python -m crllk.deploy`` or the ROS 2
node (:mod:`crllk.deployment.ros_node`) drives with it.

``out`` is checked writable before the export, and written atomically under its lock
(:func:`crllk.files.output_lock`): two exports to one file run one after the other.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from crllk.cli import run
from crllk.deployment.export import export_run
from crllk.files import output_lock, write_problem
from crllk.settings import MISSING, parse_dotlist, setting
from crllk.training.runs import CHECKPOINT_FILE, POLICY_FILE, has_policy

SOURCE = "export"
ONNX_SUFFIX = ".onnx"
DEFAULT_OUT = Path("policy.onnx")
"""Where the policy goes by default, in the run directory."""


@dataclass
class ExportConfig:
    """Command-line settings (``key=value``)."""

    run: str = setting(MISSING)
    """The run directory whose last policy is exported (its last checkpoint, or where that is
    gone its kept ``policy.pt``)."""
    out: str | None = None
    """The ONNX file to write (default: ``<run>/policy.onnx``), ending in ``.onnx``."""

    def out_path(self) -> Path:
        return Path(self.out) if self.out else Path(self.run) / DEFAULT_OUT

    def problems(self) -> Iterator[tuple[str, str]]:
        if not has_policy(self.run):
            yield "run", (f"{self.run} holds no trained run (neither {CHECKPOINT_FILE} nor "
                          f"{POLICY_FILE})")
        if self.out_path().suffix != ONNX_SUFFIX:
            yield "out", f"must end in {ONNX_SUFFIX}, got {self.out}"
        elif problem := write_problem(self.out_path()):
            yield "out", problem


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    config = parse_dotlist(ExportConfig, argv, SOURCE)
    with output_lock(config.out_path()):
        print(export_run(config.run, config.out_path()))
    return 0


if __name__ == "__main__":
    run(main)
