"""Learning algorithms, one module each, behind one interface (:class:`crllk.algos.base.Learner`).

A module of this package that defines ``LEARNER`` (a class with ``name`` and ``build``) is a
learner; ``algo.learner=<name>`` selects it, and its own settings are ``algo.options.*``, their
values in its configuration file (``crllk/conf/algo/<name>.yaml``), checked by its module when
the run is built (so composing a command's configuration imports no learner). Adding one is its
module, its configuration file and its test: nothing else in the package names a learner.
"""

from __future__ import annotations

import importlib
import pkgutil
from functools import cache

from crllk.algos.base import Learner, TrainingEnv
from crllk.config import SOURCE, TrainConfig
from crllk.errors import ConfigError

__all__ = ["Learner", "build_learner", "learners"]


@cache
def learners() -> dict[str, type[Learner]]:
    """Every learner of this package, by name."""
    found: dict[str, type[Learner]] = {}
    for module in pkgutil.iter_modules(__path__):
        learner = getattr(importlib.import_module(f"{__name__}.{module.name}"), "LEARNER", None)
        if learner is not None:
            found[learner.name] = learner
    return found


def build_learner(config: TrainConfig, env: TrainingEnv) -> Learner:
    """The learner ``algo.learner`` names, built for ``env``.

    Raises:
        ConfigError: naming the known learners, if there is none of that name.
    """
    known = learners()
    if config.algo.learner not in known:
        raise ConfigError(SOURCE, "algo.learner", f"no learner {config.algo.learner!r} "
                          f"(known: {', '.join(sorted(known))})")
    return known[config.algo.learner].build(config, env)
