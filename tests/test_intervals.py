"""Confidence intervals of an evaluation, on worked numbers."""

from __future__ import annotations

import pytest

from crllk.evaluation.intervals import mean_interval, metric_interval, wilson_interval
from crllk.evaluation.report import aggregate, constraint_intervals, format_summary
from crllk.experiments.seeds import seed_cells


def test_wilson_interval_worked_examples():
    # 3 collisions in 100 episodes: p = 0.03, z = 1.96; centre (0.03 + 1.96²/200) / (1 + 1.96²/100)
    low, high = wilson_interval(3, 100)
    assert low == pytest.approx(0.010255, abs=1e-6) and high == pytest.approx(0.084519, abs=1e-6)
    # none in 100: the interval is not empty, its upper end is z²/(n + z²)
    assert wilson_interval(0, 100)[0] == 0.0 and wilson_interval(100, 100)[1] == 1.0
    assert wilson_interval(0, 100)[1] == pytest.approx(1.959964 ** 2 / (100 + 1.959964 ** 2))
    with pytest.raises(ValueError, match="at least one trial"):
        wilson_interval(0, 0)


def test_mean_interval_worked_example():
    # mean 2.5, sample std √(5/3) = 1.291, standard error 0.645497, half width 1.959964 × 0.645497
    low, high = mean_interval([1.0, 2.0, 3.0, 4.0])
    assert (low, high) == pytest.approx((2.5 - 1.265151, 2.5 + 1.265151), abs=1e-6)
    with pytest.raises(ValueError, match="at least two values"):
        mean_interval([1.0])


def test_a_metric_of_zeros_and_ones_is_a_proportion():
    assert metric_interval([0.0] * 97 + [1.0] * 3) == wilson_interval(3, 100)
    assert metric_interval([0.1, 0.3]) == mean_interval([0.1, 0.3])


def _document(lane, collisions, run="runs/CRLLK-D-a0.5-seed0"):
    rows = [{"cost_lane": c, "cost_collision": k} for c, k in zip(lane, collisions, strict=True)]
    n = len(rows)
    summary = {"J_R": 2.0, "J_clane": sum(lane) / n, "J_coll": sum(collisions) / n,
               "episode_length": 512, "satisfied": sum(collisions) / n <= 0.02}
    return {"source": {"run_dir": run}, "evaluation": {"episodes": n}, "summary": summary,
            "episodes": rows}


def test_intervals_of_an_evaluation_and_across_runs():
    one = _document([0.2, 0.4] * 50, [0.0] * 97 + [1.0] * 3)
    two = _document([0.1, 0.3] * 50, [0.0] * 100, run="runs/CRLLK-D-a0.5-seed1")
    intervals = constraint_intervals(one)
    assert intervals["J_coll"] == pytest.approx(list(wilson_interval(3, 100)))
    assert intervals["J_clane"] == pytest.approx(list(mean_interval([0.2, 0.4] * 50)))
    result = aggregate([one, two])
    assert result["intervals"]["J_coll"][1] == pytest.approx(list(wilson_interval(0, 100)))
    assert "J_coll 0.030 per episode (95 % interval 0.010–0.085)" in format_summary(one)
    # the per-seed cells carry them, two decimals
    assert seed_cells(result) == {0: "0.300 (0.28–0.32) / 0.03 (0.01–0.08) / 2.00 ✗",
                                  1: "0.200 (0.18–0.22) / 0.00 (0.00–0.04) / 2.00 ✓"}
    # documents without their episodes: no intervals, and none across runs
    assert constraint_intervals({**one, "episodes": []}) == {}
    assert "intervals" not in aggregate([one, {**two, "episodes": []}])
