"""Typed settings with their checks beside the fields.

A settings class is a dataclass whose fields are declared with :func:`setting`: the default (one
per value, nowhere else) and the check of its range or choices. :func:`parse` merges ``key=value``
input into the class with OmegaConf (a string where a number belongs fails there), then
:func:`check` walks the fields, nested settings and dicts of settings, and calls each class's
``problems()`` for the checks that span several fields. Every failure is a
:class:`~crllk.errors.ConfigError` naming the field, e.g.
``override: ppo.gamma: must lie in [0, 1], got 1.5``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any, TypeVar

import yaml
from omegaconf import MISSING, OmegaConf
from omegaconf.errors import ConfigKeyError, OmegaConfBaseException

from crllk.errors import ConfigError
from crllk.protocol import reserved_seed_problem

Check = Callable[[Any], str | None]
"""A field's check: the problem with a value (``"must be > 0"``), or None."""
Settings = TypeVar("Settings")


def setting(default: Any = MISSING, *, check: Check | None = None) -> Any:
    """A dataclass field with its default (none: the value must be given) and its ``check``."""
    return dataclasses.field(default=default, metadata={"check": check})


def positive(value: float) -> str | None:
    return None if value > 0 else "must be > 0"


def non_negative(value: float) -> str | None:
    return None if value >= 0 else "must be >= 0"


MAX_SEED = 2**32 - 1
"""Largest seed (numpy's and torch's generators take it whole)."""
MAX_EPISODES = 1_000_000
"""Most episodes one evaluation plays (over a week of simulation per evaluation)."""
MAX_SIMULATIONS = 1024
"""Most simulations stepped together (each holds a MuJoCo model and its renderer)."""
MAX_FLEET = 8
"""Most robots a fleet evaluation puts on one map (:mod:`crllk.evaluation.fleet`)."""


def spawn_seed(value: int) -> str | None:
    """A seed of training or of a validation evaluation: not negative, at most
    :data:`MAX_SEED`, not the test seed."""
    if value > MAX_SEED:
        return f"must be at most {MAX_SEED} (2**32 - 1)"
    return non_negative(value) or reserved_seed_problem(value)


def at_most(limit: int) -> Check:
    """At least 1 and at most ``limit``."""
    def check_range(value: int) -> str | None:
        return at_least_one(value) or (None if value <= limit else f"must be at most {limit}")
    return check_range


def at_least_one(value: int) -> str | None:
    return None if value >= 1 else "must be >= 1"


def fleet_size(value: int) -> str | None:
    """0 (no fleet: the run's one robot) or 2 to :data:`MAX_FLEET` robots."""
    return None if value == 0 or 2 <= value <= MAX_FLEET else \
        f"expected 0 (one robot) or 2 to {MAX_FLEET} robots, got {value}"


def unit_interval(value: float) -> str | None:
    return None if 0 <= value <= 1 else "must lie in [0, 1]"


def open_unit_interval(value: float) -> str | None:
    return None if 0 < value < 1 else "must lie in (0, 1)"


def one_of(*choices: str) -> Check:
    """A check that the value is one of ``choices``."""

    def check(value: Any) -> str | None:
        return None if value in choices else f"must be one of {', '.join(choices)}"

    return check


def file_stem(value: str) -> str | None:
    """A plain file name without a folder: letters, digits, ``-``, ``_`` and ``.``."""
    ok = bool(value) and all(c.isalnum() or c in "-_." for c in value) and value[0] != "."
    return None if ok else "must be a plain file name (letters, digits, -, _, .)"


TCP_PORTS = 65536
"""TCP ports are 1 ... 65535."""


def tcp_port(value: int) -> str | None:
    return None if 0 < value < TCP_PORTS else f"must lie in [1, {TCP_PORTS - 1}]"


def host_port(value: str) -> str | None:
    """A network address ``host:port``, e.g. ``127.0.0.1:6379``."""
    host, _, port = value.rpartition(":")
    ok = bool(host) and port.isdigit() and tcp_port(int(port)) is None
    return None if ok else f"must be host:port with a port in [1, {TCP_PORTS - 1}]"


def parse(schema: type[Settings], values: Any, source: str, prefix: str = "") -> Settings:
    """``values`` (a mapping or an OmegaConf config) merged into ``schema`` and checked; a
    failure names the field after ``prefix`` (settings nested in a larger configuration, e.g.
    ``algo.options.``).

    Raises:
        ConfigError: naming the first field that is missing, of the wrong type or out of range.
    """
    try:
        merged = OmegaConf.merge(OmegaConf.structured(schema), values)
        settings: Settings = OmegaConf.to_object(merged)  # type: ignore[assignment]
    except ConfigKeyError as err:
        key = getattr(err, "full_key", None) or "<input>"
        raise ConfigError(source, f"{prefix}{key}", "no such setting") from None
    except OmegaConfBaseException as err:
        key = getattr(err, "full_key", None) or "<input>"
        raise ConfigError(source, f"{prefix}{key}", str(err).splitlines()[0]) from None
    check(settings, source, prefix)
    return settings


def parse_dotlist(schema: type[Settings], arguments: Iterable[str], source: str) -> Settings:
    """``key=value`` command-line arguments parsed into ``schema``."""
    arguments = list(arguments)
    for argument in arguments:
        if "=" not in argument:
            raise ConfigError(source, argument, "expected key=value")
    try:
        values = OmegaConf.from_dotlist(arguments)
    except (OmegaConfBaseException, yaml.YAMLError, ValueError) as err:
        raise ConfigError(source, _unreadable_argument(arguments), " ".join(
            str(err).split()[:24]) or type(err).__name__) from None
    return parse(schema, values, source)


def _unreadable_argument(arguments: list[str]) -> str:
    """The first ``key=value`` whose value does not parse (its key), else ``<arguments>``."""
    for argument in arguments:
        try:
            OmegaConf.from_dotlist([argument])
        except (OmegaConfBaseException, yaml.YAMLError, ValueError):
            return argument.split("=", 1)[0]
    return "<arguments>"


def check(settings: Any, source: str, prefix: str = "") -> None:
    """Runs every field's check, recursively, then the class's ``problems()``."""
    for field in dataclasses.fields(settings):
        key = f"{prefix}{field.name}"
        value = getattr(settings, field.name)
        if dataclasses.is_dataclass(value):
            check(value, source, f"{key}.")
            continue
        if isinstance(value, Mapping):
            for name, item in value.items():
                if dataclasses.is_dataclass(item):
                    check(item, source, f"{key}.{name}.")
            continue
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(source, key, f"must be finite, got {value}")
        field_check = field.metadata.get("check")
        problem = field_check(value) if field_check is not None and value is not None else None
        if problem:
            raise ConfigError(source, key, f"{problem}, got {value!r}")
    problems = getattr(settings, "problems", None)
    for field_name, problem in problems() if problems is not None else ():
        raise ConfigError(source, f"{prefix}{field_name}", problem)


__all__ = ["MISSING", "at_least_one", "check", "host_port", "non_negative", "one_of",
           "open_unit_interval", "parse", "parse_dotlist", "positive", "setting", "spawn_seed",
           "tcp_port", "unit_interval"]
