"""Builds the wheel with the top-level ``assets/mjcf`` and ``tasks`` folders copied into the
package (``crllk/shipped``), so that an installed crllk finds its robot and tasks. The
project's metadata is in ``pyproject.toml``."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

SHIPPED = ("assets/mjcf", "tasks")


class BuildWithShippedFiles(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return  # an editable install reads them from the source tree
        root = Path(__file__).resolve().parent
        for folder in SHIPPED:
            shutil.copytree(root / folder, Path(self.build_lib) / "crllk" / "shipped" / folder,
                            dirs_exist_ok=True)


setup(cmdclass={"build_py": BuildWithShippedFiles})
