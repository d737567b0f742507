"""The community's lane-following metrics (crllk.evaluation.community): the lane pose the
evaluation env reports, worked numbers per episode and over episodes, and an evaluation that
writes them."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from crllk.envs.batched import make_env
from crllk.envs.episodes import EpisodeStats, summarise
from crllk.evaluation import community
from crllk.evaluation.report import format_summary
from crllk.evaluation.runs import evaluate_follower
from crllk.maps import MapObject
from crllk.maps.routes import LANE_HALF_WIDTH
from crllk.rl.rollout import EvaluationResult
from crllk.tasks.lane_keeping import StepOutcome

SCALES = community.Scales(control_timestep=1 / 30, tile_size=0.585, vehicles=2)


def _outcome(lateral: float, on_road: bool = True) -> StepOutcome:
    return StepOutcome(0.0, lateral, 0.0, on_road, 0.0, 0, {}, None)


def test_in_lane_is_the_centre_inside_its_own_lane_on_the_road():
    assert _outcome(0.0).in_lane
    assert _outcome(-LANE_HALF_WIDTH).in_lane
    assert not _outcome(LANE_HALF_WIDTH + 0.001).in_lane
    assert not _outcome(-0.2).in_lane  # in the other lane
    assert not _outcome(0.0, on_road=False).in_lane


def test_the_evaluation_env_reports_the_lane_pose_and_training_envs_do_not():
    plain = make_env("small_loop", num_envs=2, observation="state", seed=3)
    posed = make_env("small_loop", num_envs=2, observation="state", seed=3, lane_pose=True)
    try:
        assert "lane_lateral" not in plain.observation_spec
        td = posed.reset()
        lateral = []
        for _ in range(20):
            td["action"] = torch.tensor([0, 2])
            stepped, td = posed.step_and_maybe_reset(td)
            nxt = stepped["next"]
            for i, task in enumerate(posed.tasks):
                if not nxt["done"][i]:
                    assert nxt["lane_lateral"][i, 0].item() == pytest.approx(
                        task.outcome.lateral, abs=1e-6)
                    assert bool(nxt["in_lane"][i, 0]) == task.outcome.in_lane
            lateral.append(nxt["lane_lateral"].clone())
        assert torch.stack(lateral).abs().max() > 0.0  # the robots drift from the centre
    finally:
        plain.close()
        posed.close()


def _result() -> EvaluationResult:
    episodes = [EpisodeStats(0, 1.17, {}, 300, True), EpisodeStats(1, 0.585, {}, 90, False),
                EpisodeStats(0, 2.34, {}, 60, False), EpisodeStats(1, 0.0, {}, 30, False)]
    return EvaluationResult(
        episodes=episodes, summary=summarise(episodes, ()),
        hit_objects=[None, None, 0, None], hit_movers=[None, 1, None, 2],
        lateral_deviations=[0.01, 0.02, 0.03, 0.2], outside_lane_steps=[0, 3, 6, 30])


def test_episode_metrics_worked_numbers():
    objects = [MapObject("cone", 0.0, 0.0, 0.0, 0.05, 0.05, 0.08)]
    rows = community.episode_metrics(_result(), SCALES, objects)
    assert [r["survival_time_s"] for r in rows] == pytest.approx([10.0, 3.0, 2.0, 1.0])
    assert [r["distance_tiles"] for r in rows] == pytest.approx([2.0, 1.0, 4.0, 0.0])
    assert [r["outside_lane_s"] for r in rows] == pytest.approx([0.0, 0.1, 0.2, 1.0])
    assert [r["lateral_deviation_m"] for r in rows] == [0.01, 0.02, 0.03, 0.2]
    # mover 1 is the second vehicle, mover 2 the first pedestrian; object 0 a cone
    assert [r["collided_with"] for r in rows] == [None, "vehicle", "cone", "pedestrian"]
    summary = community.summary(rows)
    assert summary["survival_time_s"] == {"median": pytest.approx(2.5), "mean": pytest.approx(4.0)}
    assert summary["distance_tiles"]["median"] == pytest.approx(1.5)
    assert summary["outside_lane_s"]["mean"] == pytest.approx(1.3 / 4)
    assert summary["collisions_by_kind"] == {"cone": 1, "pedestrian": 1, "vehicle": 1}
    line = community.format_summary(summary)
    assert "survival 2.5 s" in line and "distance 1.50 tiles" in line
    assert "cone ×1" in line and "pedestrian ×1" in line


def test_without_the_lane_pose_its_metrics_are_absent_not_zero():
    result = _result()
    result.lateral_deviations, result.outside_lane_steps = [], []
    rows = community.episode_metrics(result, SCALES)
    assert rows[0]["lateral_deviation_m"] is None and rows[0]["outside_lane_s"] is None
    summary = community.summary(rows)
    assert summary["lateral_deviation_m"] is None and summary["outside_lane_s"] is None
    assert "outside the lane" not in community.format_summary(summary)


def test_a_follower_evaluation_with_pedestrians_writes_the_community_metrics():
    document = evaluate_follower("pedestrian_loop", episodes=4, num_envs=2, seed=11,
                                 overrides={"horizon": 48})
    rows = document["episodes"]
    for row in rows:
        assert row["survival_time_s"] == pytest.approx(row["length"] / 30)
        assert row["distance_tiles"] == pytest.approx(row["distance"] / 0.585)
        assert 0.0 <= row["outside_lane_s"] <= row["survival_time_s"]
        # the lane cost is |lateral| in dm on the road: the same mean, in metres
        if row["termination"] != "off_road":
            assert row["lateral_deviation_m"] == pytest.approx(row["cost_lane"] / 10, rel=1e-4)
    summary = document["community"]
    assert summary["episodes"] == 4
    assert summary["survival_time_s"]["median"] == pytest.approx(
        float(np.median([r["survival_time_s"] for r in rows])))
    assert math.isfinite(summary["lateral_deviation_m"]["mean"])
    assert "community medians:" in format_summary(document)
