"""``python -m crllk.experiments``: see :mod:`crllk.experiments`."""

from crllk.cli import run
from crllk.experiments import main

run(main)
