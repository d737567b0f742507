"""``python -m crllk.bench``: see :mod:`crllk.bench.cli`."""

from crllk.bench.cli import main

if __name__ == "__main__":  # worker processes (spawned by --workers) import but never run it
    main()
