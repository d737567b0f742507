"""How sure an evaluation is: 95 % confidence intervals of a per-episode metric's mean.

A run is judged on the point estimate (``J ≤ α``); the interval says how far 100 episodes
pin that estimate down. A collision rate of 0.03 over 100 episodes, for instance, is
consistent with anything from about 0.01 to 0.08.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Z_95 = 1.959963984540054
"""The standard normal quantile of a two-sided 95 % interval."""


def wilson_interval(successes: float, trials: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval of a proportion (``successes`` of ``trials``): unlike the normal
    approximation it stays inside [0, 1] and is not empty when no episode failed."""
    if trials < 1:
        raise ValueError(f"a proportion needs at least one trial, got {trials}")
    p = successes / trials
    denominator = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denominator
    low = 0.0 if successes <= 0 else max(0.0, centre - half)  # exact ends, no rounding dust
    high = 1.0 if successes >= trials else min(1.0, centre + half)
    return low, high


def mean_interval(values: Sequence[float], z: float = Z_95) -> tuple[float, float]:
    """Normal interval of a mean, ``mean ± z·s/√n`` (sample standard deviation, ddof 1)."""
    n = len(values)
    if n < 2:
        raise ValueError(f"an interval of a mean needs at least two values, got {n}")
    mean = sum(values) / n
    variance = sum((v - mean) ** 2 for v in values) / (n - 1)
    half = z * math.sqrt(variance / n)
    return mean - half, mean + half


def metric_interval(values: Sequence[float]) -> tuple[float, float]:
    """The interval of a per-episode metric's mean: Wilson's where every episode scores 0 or 1
    (a collision ends an episode, so J_coll is the fraction of episodes that ended on one),
    the normal one of the mean otherwise."""
    if all(v in (0.0, 1.0) for v in values):
        return wilson_interval(sum(values), len(values))
    return mean_interval(values)

