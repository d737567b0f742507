"""The evaluation protocol: validation seeds for every decision, one test seed for the tables.

- **Validation** (:data:`VALIDATION_SEED`): the trainer's evaluations (``eval.csv``, the run's
  ``eval.json``), ``python -m crllk.evaluate``'s default, and every choice of a setting.
- **Test** (:data:`TEST_SEED`): the table experiments only (``python -m crllk.experiments``),
  once per finished run, :data:`TEST_EPISODES` episodes, written to the run's ``test.json``
  (sampled policy) and ``test-mode.json`` (deployed policy). The trainer refuses it as a
  training or evaluation seed and ``crllk.evaluate`` refuses it, so no result on it can steer a
  setting.

Spawns come from ``numpy.random.SeedSequence(seed)``, so the validation, test and training
seeds' simulations draw from independent streams.
"""

from __future__ import annotations

VALIDATION_SEED = 1_000_000
"""Spawn (and sampling) seed of the validation evaluations, far from every training seed."""
VALIDATION_EPISODES = 100
"""Episodes of a validation evaluation (the trainer's ``eval.episodes``)."""
TEST_SEED = 31_415_926
"""Spawn (and sampling) seed of the test evaluations: the tables' only evaluation seed."""
TEST_EPISODES = 400
"""Episodes of a test evaluation: enough to resolve a collision rate near α2 = 0.02."""
TEST_EVALUATION = "test"
"""A run's test evaluation of its sampled policy: ``<run>/test.json``."""
TEST_MODE_EVALUATION = "test-mode"
"""A run's test evaluation of its deployed policy (a discrete run's expected duties, a
continuous run's expected action): ``<run>/test-mode.json``."""


def reserved_seed_problem(seed: int | None) -> str | None:
    """Why ``seed`` cannot seed training or a validation evaluation (None: it can)."""
    if seed == TEST_SEED:
        return ("must not be the test seed, which only the table experiments evaluate on "
                "(python -m crllk.experiments)")
    return None


__all__ = ["TEST_EPISODES", "TEST_EVALUATION", "TEST_MODE_EVALUATION", "TEST_SEED",
           "VALIDATION_EPISODES", "VALIDATION_SEED", "reserved_seed_problem"]
