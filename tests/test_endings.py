"""``python -m crllk.analysis.endings``: the last seconds of the episodes that leave the road,
with worked numbers for its figures and a policy made to leave the road."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from tiny_runs import run_in_process

from crllk.analysis.endings import Step, ending, summary, swings
from crllk.tasks.actions import DISCRETE_DUTIES, DISCRETE_NAMES


def test_swings_count_side_changes_of_turns_beyond_the_threshold():
    # sides beyond 0.2: +, -, -, +  (0.1 and 0.05 are too small to count)
    assert swings([0.5, 0.1, -0.4, -0.3, 0.6, 0.05]) == 2
    assert swings([0.36, 0.36, 0.36]) == 0
    assert swings([0.1, -0.1, 0.1]) == 0
    assert swings([]) == 0


def test_an_ending_s_figures_worked():
    """Three steps: laterals 0.06, 0.08, 0.10 m (mean 0.08, last 0.10), headings -10°..+20°,
    turns 0.36, -0.36, 0 (mean |turn| 0.24, one swing), the nearest mover 0.5 m away at the
    end."""
    window = [Step(0.06, math.radians(-10), 0.36, 0.9), Step(0.08, math.radians(20), -0.36, 0.7),
              Step(0.10, math.radians(5), 0.0, 0.5)]
    found = ending("off_road", (3, 1), "straight", window)
    assert found.steps == 3 and found.tile == (3, 1) and found.tile_kind == "straight"
    assert found.mean_lateral == pytest.approx(0.08) and found.final_lateral == 0.10
    assert found.heading_error_deg == pytest.approx((-10.0, 20.0))
    assert found.mean_abs_turn == pytest.approx(0.24)
    assert found.swings == 1 and found.mover_distance == 0.5
    assert ending("off_road", (3, 1), "straight", [Step(0.1, 0.0, 0.0, math.inf)]) \
        .mover_distance is None
    other = ending("collision", (1, 2), "curve_left", window[:1])
    counts = summary([found, other], episodes=10)
    assert counts["episodes"] == 10 and counts["endings"] == 2
    assert counts["by_termination"] == {"off_road": 1, "collision": 1}
    assert counts["by_tile_kind"] == {"straight": 1, "curve_left": 1}
    assert counts["median_mean_lateral"] == pytest.approx((0.08 + 0.06) / 2)
    assert summary([], episodes=3)["median_swings"] is None


@pytest.fixture(scope="module")
def straight_run(tmp_path_factory) -> Path:
    """A tiny state run whose policy always drives straight on, in 300-step episodes: it
    leaves the road of small_loop at a curve."""
    run = run_in_process(tmp_path_factory.mktemp("endings") / "run", 1,
                         ["obs=state", "task.horizon=300"])
    shutil.rmtree(run / "checkpoints")  # the kept policy.pt is then what runs
    weights = torch.load(run / "policy.pt", weights_only=True)
    state = weights["actor"]
    biases = [k for k, v in state.items() if k.endswith("bias") and v.shape == (3,)]
    assert len(biases) == 1, list(state)
    last = biases[0]
    weight = last[: -len("bias")] + "weight"
    state[weight].zero_()
    state[last].copy_(torch.tensor([-20.0, -20.0, 20.0]))  # straight, always
    torch.save(weights, run / "policy.pt")
    return run


def test_a_policy_that_drives_straight_on_leaves_the_road_at_a_curve(straight_run):
    from crllk.analysis import endings

    assert DISCRETE_NAMES[2] == "straight"
    straight_turn = float(DISCRETE_DUTIES[2, 1] - DISCRETE_DUTIES[2, 0])
    assert endings.main([str(straight_run), "--episodes", "3", "--seconds", "0.5"]) == 0
    document = json.loads((straight_run / "endings.json").read_text())
    assert document["seed"] == 1_000_000 and document["task"] == "small_loop"
    assert document["summary"]["episodes"] == 3
    assert document["summary"]["by_termination"] == {"off_road": 3}
    for found in document["endings"]:
        assert found["steps"] == 15  # 0.5 s at 30 Hz
        assert found["tile_kind"].startswith("curve")
        assert found["mean_abs_turn"] == pytest.approx(abs(straight_turn))
        assert found["swings"] == 0 and found["mover_distance"] is None  # no movers


def test_bad_input_is_one_line(straight_run, tmp_path):
    for argv, message in (([str(tmp_path / "none")], "no such run directory"),
                          ([str(straight_run), "--seconds", "0"], "--seconds: must be a positive"),
                          ([str(straight_run), "--episodes", "0"], "--episodes")):
        completed = subprocess.run([sys.executable, "-m", "crllk.analysis.endings", *argv],
                                   capture_output=True, text=True, timeout=120)
        assert completed.returncode == 2, completed.stderr
        assert message in completed.stderr
        assert len(completed.stderr.strip().splitlines()) == 1
