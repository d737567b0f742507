"""Fleet evaluation (:mod:`crllk.tasks.fleet`, :mod:`crllk.evaluation.fleet`): every robot on the
map driven by one policy, each in its own simulation where the others are its movers. Probes
of where each simulation puts the other robots, a head-on collision that ends both robots'
episodes, spawns kept apart, and the command with its bad inputs. Real MuJoCo throughout."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_runs import run_in_process

from crllk.envs.batched import make_env
from crllk.evaluation.fleet import (
    FLEET_CLEARANCE,
    evaluate_fleet,
    fleet_traffic,
    join_fleet,
    play_fleet,
    start_apart,
)
from crllk.maps.obstacles import footprint_gap
from crllk.tasks.actions import DISCRETE_NAMES
from crllk.tasks.fleet import PARKED, FleetBoard
from crllk.tasks.traffic import duckiebot_box

REPO = Path(__file__).resolve().parents[1]
STRAIGHT = DISCRETE_NAMES.index("straight")


def fleet_env(robots: int, seed: int = 0, horizon: int = 64):
    """``robots`` simulations of small_loop, each with a mover per other robot, joined."""
    env = make_env("small_loop", num_envs=robots, observation="state", action="discrete",
                   seed=seed, lane_pose=True,
                   overrides={"horizon": horizon, "traffic": fleet_traffic(robots)})
    return env, join_fleet(env)


def straight(td):
    td["action"] = torch.full(td.batch_size, STRAIGHT, dtype=torch.int64)
    return td


def test_the_board_gives_each_robot_the_others_in_order():
    board = FleetBoard([(0.0, 0.0, 0.0), (1.0, 0.0, 0.5), (2.0, 1.0, 1.0)])
    assert board.others(1) == [(0.0, 0.0, 0.0), (2.0, 1.0, 1.0)]
    board.active[2] = False
    assert board.others(0) == [(1.0, 0.0, 0.5), PARKED]
    assert [board.robot_of_mover(1, m) for m in (0, 1)] == [0, 2]
    assert [board.robot_of_mover(0, m) for m in (0, 1)] == [1, 2]


def test_each_simulation_shows_the_other_robots_where_their_simulations_have_them():
    """Three robots driving straight for 20 steps: before every step, simulation i's movers
    stand (mocap body at the axle, wheel-radius high) where simulations j != i held their
    robots, and the task measures them there."""
    env, board = fleet_env(3)
    td = start_apart(env, board)
    with torch.no_grad():
        for _ in range(20):
            poses = [physics.pose() for physics in env.physics]
            board.poses = poses
            td = env.step(straight(td))
            td = td["next"].clone()
            for i, (physics, task) in enumerate(zip(env.physics, env.tasks, strict=True)):
                others = [p for k, p in enumerate(poses) if k != i]
                assert task.traffic.poses(task.episode.traffic) == others
                mocap = physics.data.mocap_pos[physics.movers.mocap]
                np.testing.assert_allclose(mocap[:, :2], np.array(others)[:, :2], atol=1e-12)
    env.close()


def face_to_face(env) -> None:
    """Robot 1 0.35 m ahead of robot 0, facing it."""
    x, y, yaw = env.physics[0].pose()
    env.physics[1].set_pose(x + 0.35 * math.cos(yaw), y + 0.35 * math.sin(yaw), yaw + math.pi)
    env.physics[1].forward()


def test_the_first_camera_frame_shows_the_other_robots():
    """The observation a fleet episode starts from already has the other robots in it: robot
    0's first frame is its camera's image with robot 1 0.35 m ahead, which differs from the
    same view without it in more than 3 % of the pixels."""
    env = make_env("small_loop", num_envs=2, observation="pixels", action="discrete", seed=0,
                   lane_pose=True, overrides={"traffic": fleet_traffic(2)})
    board = join_fleet(env)
    first = start_apart(env, board, face_to_face)["pixels"][0].numpy()
    physics = env.physics[0]
    np.testing.assert_array_equal(first, env.tasks[0].camera_image(physics))
    physics.set_mover_poses([PARKED])
    physics.forward()
    without = env.tasks[0].camera_image(physics)
    env.close()
    changed = np.any(first != without, axis=-1)
    assert changed.mean() > 0.03  # robot 1 covers about 6 % of the image


def test_robots_driving_head_on_both_collide_with_each_other():
    """Robot 1 placed 0.35 m ahead of robot 0 in its lane, facing it; both drive straight:
    both episodes end in a collision within 30 steps, each having hit the other."""
    env, board = fleet_env(2)

    result, hit_robots = play_fleet(env, straight, board, 1, deterministic=True,
                                    arrange=face_to_face)
    env.close()
    assert result.terminations == ["collision", "collision"]
    assert all(e.length < 30 for e in result.episodes)
    assert hit_robots == [1, 0]
    assert result.hit_movers == [0, 0]
    assert [e.costs["collision"] for e in result.episodes] == [1.0, 1.0]


def min_gap(env) -> float:
    """The smallest gap (m) between two robots' footprints."""
    boxes = [duckiebot_box(*physics.pose()) for physics in env.physics]
    return min(footprint_gap(a, b) for k, a in enumerate(boxes) for b in boxes[k + 1:])


def across_the_lane_ahead(env) -> None:
    """Robot 1 0.2 m ahead of robot 0, across its lane (it drives out of robot 0's path)."""
    x, y, yaw = env.physics[0].pose()
    env.physics[1].set_pose(x + 0.2 * math.cos(yaw), y + 0.2 * math.sin(yaw), yaw + math.pi / 2)
    env.physics[1].forward()


def test_a_robot_driven_into_ends_its_episode_too():
    """Robot 0 drives into robot 1, which crosses its lane ahead and moves away from it: only
    robot 0's simulation sees the contact (robot 1's shows robot 0 where it stood before the
    step), yet both episodes end on that step with a collision, each naming the other."""
    env, board = fleet_env(2)
    result, hit_robots = play_fleet(env, straight, board, 1, deterministic=True,
                                    arrange=across_the_lane_ahead)
    env.close()
    assert result.terminations == ["collision", "collision"]
    assert result.episodes[0].length == result.episodes[1].length < 30
    assert hit_robots == [1, 0]
    assert [e.costs["collision"] for e in result.episodes] == [1.0, 1.0]
    assert result.hit_objects == [None, None]


def test_spawns_keep_the_robots_apart():
    """Over eight fleet starts of six robots on small_loop, every pair of footprints is at
    least FLEET_CLEARANCE apart, where the simulations' own spawns (a plain reset) put two
    closer in some."""
    env, board = fleet_env(6, seed=3)
    crowded = 0
    for _ in range(8):
        env.reset()
        crowded += min_gap(env) < FLEET_CLEARANCE
        start_apart(env, board)
        assert min_gap(env) >= FLEET_CLEARANCE
    env.close()
    assert crowded > 0
    docs = " ".join((REPO / "docs/evaluation.md").read_text().split())
    assert f"until its footprint is at least {FLEET_CLEARANCE} m from the others'" in docs


@pytest.fixture(scope="module")
def pixel_run(tmp_path_factory) -> Path:
    return run_in_process(tmp_path_factory.mktemp("fleet") / "pixels", 1, ["obs=pixels"])


def test_a_fleet_evaluation_writes_one_row_per_robot_and_episode(pixel_run):
    document = evaluate_fleet(pixel_run, robots=3, episodes=2, seed=5)
    assert json.loads((pixel_run / "fleet.json").read_text()) == document
    settings = document["evaluation"]
    assert settings["robots"] == 3 and settings["episodes"] == 6
    assert [row["env_index"] for row in document["episodes"]] == [0, 1, 2] * 2
    by_robot = document["fleet"]["by_robot"]
    assert [entry["episodes"] for entry in by_robot] == [2, 2, 2]
    rows = document["episodes"]
    for robot, entry in enumerate(by_robot):
        own = [row["cost_lane"] for row in rows if row["env_index"] == robot]
        assert entry["J_clane"] == pytest.approx(np.mean(own))
    assert len(document["fleet"]["hit_robots"]) == 6
    again = evaluate_fleet(pixel_run, robots=3, episodes=2, seed=5, name="fleet-again")
    assert again["episodes"] == document["episodes"]


@pytest.mark.parametrize(("args", "message"), [
    (["fleet=1"], "fleet: expected 0 (one robot) or 2 to 8 robots, got 1"),
    (["fleet=9"], "fleet: expected 0 (one robot) or 2 to 8 robots, got 9"),
    (["fleet=2", "record=true"], "record: fleet evaluations are not recorded"),
])
def test_bad_fleets_fail_clearly(pixel_run, args, message):
    result = subprocess.run([sys.executable, "-m", "crllk.evaluate", f"run={pixel_run}",
                             "episodes=1", *args], cwd=REPO, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 2
    assert message in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_fleet_without_a_run_fails_clearly():
    result = subprocess.run([sys.executable, "-m", "crllk.evaluate", "follower=true",
                             "fleet=3"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert "fleet: a fleet is driven by a run's policy" in result.stderr


def test_fleets_the_task_cannot_hold_fail_clearly(tmp_path, pixel_run):
    """A map with obstacles on the road, and a state policy trained without movers; on the
    command line, every run is checked before the first is evaluated."""
    from crllk.errors import ConfigError

    obstacles = run_in_process(tmp_path / "obstacles", 1, ["obs=state", "task=obstacle_loop"])
    with pytest.raises(ConfigError, match=r"overrides\.traffic: movers do not avoid obstacles"):
        evaluate_fleet(obstacles, robots=2, episodes=1)
    plain = run_in_process(tmp_path / "plain", 1, ["obs=state"])
    with pytest.raises(ConfigError, match="a state policy trained without traffic"):
        evaluate_fleet(plain, robots=2, episodes=1)
    result = subprocess.run([sys.executable, "-m", "crllk.evaluate", f"runs=[{pixel_run},{plain}]",
                             "fleet=2", "episodes=1", "name=checked-first"], cwd=REPO,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stderr
    assert "a state policy trained without traffic" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (pixel_run / "checked-first.json").exists()  # nothing played


def test_a_map_too_crowded_for_the_fleet_fails_clearly(monkeypatch):
    """Where a robot finds no spawn apart from the others, the fleet is refused as a setting
    (with one try per robot, six robots on small_loop are crowded in some of eight starts)."""
    import crllk.evaluation.fleet as fleet
    from crllk.errors import ConfigError

    monkeypatch.setattr(fleet, "SPAWN_TRIES", 1)
    env, board = fleet_env(6, seed=3)
    with pytest.raises(ConfigError, match=r"fleet: no spawn of robot \d keeps .* fewer robots"):
        for _ in range(8):
            start_apart(env, board)
    env.close()


def test_a_fleet_result_is_named_fleet_unless_named(tmp_path):
    from crllk.evaluate import parse

    def result(*args: str) -> str:
        return parse([f"run={tmp_path}", *args]).result_file(tmp_path).name

    assert result("fleet=2") == "fleet.json"
    assert result("fleet=2", "name=eval") == "eval.json"
    assert result() == "eval.json"
    assert result("name=x") == "x.json"
