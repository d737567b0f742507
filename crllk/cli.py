"""Command-line helpers shared by the commands: bad arguments end with one line."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable
from typing import NoReturn

from crllk.errors import ConfigError


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line, ``error: <problem>``, and exit 2."""

    def error(self, message: str) -> NoReturn:
        print(f"error: {message}", file=sys.stderr)
        raise SystemExit(2)


def _whole_number_at_least(text: str, least: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < least:
        raise argparse.ArgumentTypeError(f"must be at least {least}, got {value}")
    return value


def positive_int(text: str) -> int:
    """A whole number above zero (an argparse ``type``)."""
    return _whole_number_at_least(text, 1)


def non_negative_int(text: str) -> int:
    """A whole number of at least zero (an argparse ``type``)."""
    return _whole_number_at_least(text, 0)


def positive_float(text: str) -> float:
    """A finite number above zero (an argparse ``type``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number above 0, got {text}")
    return value


DEBUG_VARIABLE = "CRLLK_DEBUG"
"""Set (``CRLLK_DEBUG=1``) to see the traceback of an error instead of its one line."""


def run(main: Callable[[], object]) -> NoReturn:
    """Runs a command's ``main`` and exits with its status (:func:`exit_status`)."""
    raise SystemExit(exit_status(main))


def exit_status(main: Callable[[], object]) -> int:
    """Calls ``main``; its status (an int it returns, else 0). Bad input (a
    :class:`~crllk.errors.ConfigError`, or a file that cannot be read or written) is one line
    and status 2, any other error one line naming it and status 1; the traceback only with
    ``CRLLK_DEBUG=1``."""
    debug = os.environ.get(DEBUG_VARIABLE, "") not in ("", "0")
    try:
        status = main()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except (ConfigError, OSError) as err:
        if debug:
            raise
        print(f"error: {one_line(err)}", file=sys.stderr)
        return 2
    except Exception as err:
        if debug:
            raise
        print(f"error: {type(err).__name__}: {one_line(err)} ({DEBUG_VARIABLE}=1 shows where)",
              file=sys.stderr)
        return 1
    return status if isinstance(status, int) and not isinstance(status, bool) else 0


def one_line(err: BaseException) -> str:
    """An exception's message on one line (an OSError as ``<file>: <reason>``)."""
    if isinstance(err, OSError) and err.strerror:
        where = f"{err.filename}: " if err.filename else ""
        return f"{where}{err.strerror}"
    return " ".join(str(err).split()) or type(err).__name__


def fail(problem: object) -> NoReturn:
    """Ends the command with ``error: <problem>`` on one line and exit status 2."""
    print(f"error: {problem}", file=sys.stderr)
    raise SystemExit(2)
