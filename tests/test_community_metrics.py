"""The community's lane-following metrics (crllk.evaluation.community): the lane pose the
evaluation env reports, worked numbers per episode and over episodes, and an evaluation that
writes them."""

from __future__ import annotations

import dataclasses
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
from crllk.maps.markings import lane_edges
from crllk.rl.rollout import EvaluationResult
from crllk.tasks.lane_keeping import load

SCALES = community.Scales(control_timestep=1 / 30, tile_size=0.585, vehicles=2)


def test_the_lane_s_edges_are_its_tapes_inner_edges():
    """21.75 cm between the yellow centre tape (2.4 cm wide, its middle 11.7 cm left of the
    lane centre) and the white edge tape (4.8 cm wide, 1.5 cm inside the tile's edge) on a
    58.5 cm tile."""
    left, right = lane_edges(0.585)
    assert left == pytest.approx(-0.105) and right == pytest.approx(0.1125)


@pytest.mark.parametrize(("lateral", "on_road", "termination", "expected"), [
    (0.0, True, None, True), (-0.104, True, None, True), (0.112, True, None, True),
    (-0.106, True, None, False), (0.113, True, None, False), (-0.2, True, None, False),
    (0.0, False, None, False), (0.1, True, "off_road", False), (0.0, True, "collision", True)])
def test_in_lane_is_the_centre_between_the_lane_edges_on_the_road(lateral, on_road,
                                                                  termination, expected):
    """The step's outcome: on the road, not ended off it, the centre between the edges (the
    other lane is outside; a step that ends off the road is outside wherever the centre is)."""
    env = load("small_loop", observation="state", seed=0)
    task = env.task
    pose = dataclasses.replace(task.map.lane_pose(*task.map.lanes[0].point_at(0.1)),
                               lateral=lateral, on_road=on_road)
    outcome = task._outcome(0.0, pose, {}, termination)
    assert outcome.in_lane is expected
    env.physics.free_renderers()


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


def test_each_episode_s_lane_pose_sums_are_its_own():
    """Episodes of unequal lengths (driving straight on leaves the road at different times, and a
    simulation plays on past its quota): each episode's mean |lateral| and steps outside the
    lane are those of its own steps, counted here step by step from the same seeds."""
    from crllk.rl.rollout import run_episodes

    def straight_on(td):
        td.set("action", torch.full((2,), 2, dtype=torch.int64))
        return td

    env = make_env("small_loop", num_envs=2, observation="state", seed=4, lane_pose=True)
    try:
        result = run_episodes(env, straight_on, 3)
    finally:
        env.close()
    replay = make_env("small_loop", num_envs=2, observation="state", seed=4, lane_pose=True)
    episodes: list[list[tuple[float, int]]] = [[], []]
    current: list[list[tuple[float, bool]]] = [[], []]
    td = replay.reset()
    try:
        while len(episodes[0]) < 2 or len(episodes[1]) < 1:
            stepped, td = replay.step_and_maybe_reset(straight_on(td))
            nxt = stepped["next"]
            for i in range(2):
                current[i].append((float(nxt["lane_lateral"][i, 0]), bool(nxt["in_lane"][i, 0])))
                if nxt["done"][i]:
                    steps = current[i]
                    episodes[i].append((sum(abs(lat) for lat, _ in steps) / len(steps),
                                        sum(not inside for _, inside in steps)))
                    current[i] = []
    finally:
        replay.close()
    expected = [episodes[0][0], episodes[1][0], episodes[0][1]]  # episode k in simulation k % 2
    assert [stats.length for stats in result.episodes] != [result.episodes[0].length] * 3
    assert result.lateral_deviations == pytest.approx([e[0] for e in expected], rel=1e-6)
    assert result.outside_lane_steps == [e[1] for e in expected]
    assert any(count > 0 for count in result.outside_lane_steps)
