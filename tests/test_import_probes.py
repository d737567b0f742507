"""The tensordict probe workaround: the same answers, from sys.modules."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import importlib.util, sys
import crllk.rl.import_probes as probes
installed = importlib.util.find_spec("pandas") is not None
marked = probes.settle_import_probes()
assert (marked == []) == installed, marked
assert (importlib.util.find_spec("pandas") is None) == (not installed)
probes.PROBED = ("json",)  # an installed module is left alone
assert probes.settle_import_probes() == [] and importlib.util.find_spec("json") is not None
if not installed:
    try:
        import pandas  # noqa: F401
    except ImportError:
        print("absent")
"""


def test_probes_answer_the_same_from_sys_modules():
    completed = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                               timeout=60)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.strip() in ("absent", "")
