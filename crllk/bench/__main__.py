"""``python -m crllk.bench``: see :mod:`crllk.bench.cli`."""

from crllk.bench.cli import main

main()
