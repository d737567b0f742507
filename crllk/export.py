"""``python -m crllk.export run=<run_dir> [out=<file>.onnx]``: a run's policy as ONNX.

Writes the deterministic policy (:mod:`crllk.deployment.export`): one camera image as uint8
30×40×3 RGB (pixel runs) or the state features (state runs) in, the two wheel duty cycles
out. Default ``out``: ``<run_dir>/policy.onnx``. Then ``python -m crllk.deploy`` or the ROS 2
node (:mod:`crllk.deployment.ros_node`) drives with it.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from crllk.cli import run
from crllk.deployment.export import export_run
from crllk.files import write_problem
from crllk.settings import MISSING, parse_dotlist, setting
from crllk.training.runs import CHECKPOINT_FILE, POLICY_FILE, has_policy

SOURCE = "export"


@dataclass
class ExportConfig:
    """Command-line settings (``key=value``)."""

    run: str = setting(MISSING)
    """The run directory whose last policy is exported (its last checkpoint, or where that is
    gone its kept ``policy.pt``)."""
    out: str | None = None
    """The ONNX file to write (default: ``<run>/policy.onnx``)."""

    def problems(self) -> Iterator[tuple[str, str]]:
        if not has_policy(self.run):
            yield "run", (f"{self.run} holds no trained run (neither {CHECKPOINT_FILE} nor "
                          f"{POLICY_FILE})")
        problem = write_problem(self.out or Path(self.run) / "policy.onnx")
        if problem:
            yield "out", problem


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    config = parse_dotlist(ExportConfig, argv, SOURCE)
    print(export_run(config.run, config.out))
    return 0


if __name__ == "__main__":
    run(main)
