"""Peer libraries on crllk's tasks: the task served over JSON lines to another Python, the one
cost it gives a single-constraint learner (worked numbers), a peer's policy played back in
crllk's evaluation (checked against the library's own actions), and the peers table's
arithmetic. The policy under ``tests/data/peer_run`` is a real OmniSafe 0.5.0 PPOLag policy
(``peers/omnisafe/train.py --frames 2048 --steps-per-epoch 1024``): OmniSafe itself needs its
own Python 3.10 environment (``make peers``), which the tests do not."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from crllk.errors import ConfigError
from crllk.evaluation.peer_runs import evaluate_peer, load_peer_actor, read_peer
from crllk.experiments.peers import best_tracker, time_to_constraints, worst_ratio
from crllk.gym import LaneKeepingEnv
from crllk.paths import task_file
from crllk.peers.env_server import COST_LIMIT, episode_end_correction, scalar_cost
from crllk.protocol import TEST_SEED, VALIDATION_SEED
from crllk.tasks.constraints import BUILTIN

REPO = Path(__file__).resolve().parent.parent
PEER_RUN = REPO / "tests" / "data" / "peer_run" / "small_loop" / "OmniSafe-PPOLag-a0.5-seed0"
PAPER = (BUILTIN["lane"], BUILTIN["collision"])
ALPHAS = {"lane": 0.5, "collision": 0.02}


# ----- the single cost -----------------------------------------------------------------------
def test_scalar_cost_worked_numbers():
    # lane 0.256 dm on one step of 512 at alpha_1 0.5: 0.256 / (0.5 * 512) = 0.001
    assert scalar_cost({"lane": 0.256, "collision": 0.0}, PAPER, ALPHAS, 512) == \
        pytest.approx(0.001)
    # a collision alone: 1 / 0.02 = 50, fifty times the episode's limit
    assert scalar_cost({"lane": 0.0, "collision": 1.0}, PAPER, ALPHAS, 512) == \
        pytest.approx(50.0)
    # a full episode 0.25 dm off the centre, no collision: 512 * 0.25 / 256 = 0.5
    # = J_clane / alpha_1, inside the limit of 1; at 0.5 dm it is exactly 1
    total = sum(scalar_cost({"lane": 0.25, "collision": 0.0}, PAPER, ALPHAS, 512)
                for _ in range(512))
    assert total == pytest.approx(0.5)
    assert COST_LIMIT == 1.0


def test_an_episode_that_ends_early_costs_its_own_mean():
    # 100 steps, 30 dm of lane deviation in all, horizon 512, alpha_1 = 0.5: the steps gave
    # 30 / (0.5 * 512) = 0.1171875, the episode's value is (30 / 100) / 0.5 = 0.6, so its last
    # step adds 30 * (1/100 - 1/512) / 0.5 = 0.4828125
    correction = episode_end_correction({"lane": 30.0, "collision": 1.0}, 100, PAPER, ALPHAS,
                                        512)
    assert correction == pytest.approx(0.4828125)
    assert 30.0 / (0.5 * 512) + correction == pytest.approx(0.6)
    assert episode_end_correction({"lane": 30.0, "collision": 0.0}, 512, PAPER, ALPHAS,
                                  512) == 0.0


# ----- the task server -----------------------------------------------------------------------
def _short_task(tmp_path: Path, horizon: int = 6) -> Path:
    settings = yaml.safe_load(task_file("small_loop").read_text())
    settings["horizon"] = horizon
    path = tmp_path / "short_loop.yaml"
    path.write_text(yaml.safe_dump(settings))
    return path


def _serve(task: Path, log: Path, requests: list[object]) -> subprocess.CompletedProcess:
    lines = "".join((r if isinstance(r, str) else json.dumps(r)) + "\n" for r in requests)
    return subprocess.run([sys.executable, "-m", "crllk.peers.env_server", f"task={task}",
                           f"log={log}"], input=lines, capture_output=True, text=True,
                          timeout=300, cwd=REPO)


def test_the_server_plays_the_task_as_the_gymnasium_adapter_does(tmp_path):
    task, log = _short_task(tmp_path), tmp_path / "episodes.csv"
    actions = [[0.8, 0.1 * k] for k in range(6)]
    done = _serve(task, log, [{"reset": 3}, *({"step": a} for a in actions), {"close": True}])
    assert done.returncode == 0, done.stderr
    description, start, *steps = (json.loads(line) for line in done.stdout.splitlines())
    assert description == {"observation_size": 24, "action_size": 2, "horizon": 6,
                           "cost_limit": 1.0, "thresholds": ALPHAS}
    env = LaneKeepingEnv(task, observation="state", action="continuous")
    observation, _ = env.reset(seed=3)
    np.testing.assert_array_equal(np.float32(start["observation"]), observation)
    for action, reply in zip(actions, steps, strict=True):
        observation, reward, terminated, truncated, info = env.step(np.float32(action))
        np.testing.assert_array_equal(np.float32(reply["observation"]), observation)
        assert reply["reward"] == reward
        assert reply["costs"] == {"lane": info["cost_lane"], "collision": info["cost_collision"]}
        assert reply["cost"] == pytest.approx(scalar_cost(reply["costs"], PAPER, ALPHAS, 6))
        assert (reply["terminated"], reply["truncated"]) == (terminated, truncated)
    env.close()
    assert steps[-1]["truncated"]
    rows = log.read_text().splitlines()
    assert rows[0] == "frames,time_s,episodes,J_R,J_clane,J_coll,episode_length"
    frames, _, episodes, distance, lane, collisions, length = rows[1].split(",")
    assert (frames, episodes, collisions, length) == ("6", "1", "0", "6")
    assert float(distance) == pytest.approx(sum(s["reward"] for s in steps), rel=1e-5)
    assert float(lane) == pytest.approx(np.mean([s["costs"]["lane"] for s in steps]), rel=1e-5)


def test_an_episode_s_costs_add_up_to_its_values_over_their_thresholds(tmp_path):
    """Steering hard leaves the road long before the horizon: the costs the server sent over
    the episode sum to J_clane / alpha_1 + J_coll / alpha_2 of that episode, exactly."""
    task, log = _short_task(tmp_path, horizon=400), tmp_path / "episodes.csv"
    done = _serve(task, log, [{"reset": 0}, *({"step": [1.0, 1.0]} for _ in range(400))])
    replies = [json.loads(line) for line in done.stdout.splitlines()[2:]]
    ended = next(k for k, r in enumerate(replies) if r["terminated"] or r["truncated"])
    assert replies[ended]["terminated"] and ended < 399
    header, values = (line.split(",") for line in log.read_text().splitlines()[:2])
    row = dict(zip(header, values, strict=True))
    assert int(row["episode_length"]) == ended + 1
    assert sum(r["cost"] for r in replies[:ended + 1]) == pytest.approx(
        float(row["J_clane"]) / 0.5 + float(row["J_coll"]) / 0.02, rel=1e-5)
    # the server then wants a reset
    assert done.returncode == 2 and "step: no episode under way: reset first" in done.stderr


@pytest.mark.parametrize(("request_line", "problem"), [
    ({"reset": -1}, "reset: seed must be >= 0"),
    ({"step": [0.5, 0.0]}, "step: no episode under way: reset first"),
    ({"reset": TEST_SEED}, "reset: seed must not be the test seed"),
    ("not json", "request: not JSON"),
    ({"jump": 1}, "request: expected one of reset, step, close, got 'jump'"),
    ({"reset": 1.5}, "reset: expected a whole-number seed or null"),
])
def test_the_server_answers_a_bad_request_with_one_line(tmp_path, request_line, problem):
    done = _serve(_short_task(tmp_path), tmp_path / "log.csv", [request_line])
    assert done.returncode == 2
    assert done.stderr.strip().count("\n") == 0
    assert f"crllk.peers.env_server: {problem}" in done.stderr
    assert "error" in json.loads(done.stdout.splitlines()[-1])


def test_the_server_refuses_an_action_that_is_not_two_finite_numbers(tmp_path):
    done = _serve(_short_task(tmp_path), tmp_path / "log.csv",
                  [{"reset": 1}, {"step": [1.0, math.nan]}])
    assert done.returncode == 2
    assert "step: action: expected 2 finite numbers" in done.stderr


# ----- a peer's policy -----------------------------------------------------------------------
def test_the_peer_policy_plays_the_library_s_own_actions():
    _, peer = load_peer_actor(PEER_RUN, 24, 2)  # checks the probe inside
    assert (peer["library"], peer["algo"], peer["task"]) == ("omnisafe", "PPOLag", "small_loop")
    assert len(peer["probe"]["states"]) == 8


def test_the_library_normalised_each_observation_once():
    """Features 8 and 11 stay 1.5 on small_loop (nothing ahead): a normaliser fed each
    observation once keeps mean 1.5 and its floor std 0.01; fed the already normalised copy
    too (an info entry aliasing the observation), its statistics drift (mean 1.24, std 0.26)."""
    arrays = np.load(PEER_RUN / "policy.npz")
    np.testing.assert_allclose(arrays["obs_mean"][[8, 11]], 1.5, rtol=1e-6)
    np.testing.assert_allclose(arrays["obs_std"][[8, 11]], 0.01, rtol=1e-6)


def _copy_run(tmp_path: Path) -> Path:
    copy = tmp_path / "run-seed0"
    shutil.copytree(PEER_RUN, copy)
    return copy


def test_a_changed_policy_is_refused_by_its_probe(tmp_path):
    run = _copy_run(tmp_path)
    arrays = dict(np.load(run / "policy.npz"))
    arrays["layer2.bias"] = arrays["layer2.bias"] + 0.01
    np.savez(run / "policy.npz", **arrays)
    with pytest.raises(ConfigError, match=r"policy.npz: policy: plays actions 0.01 from the "):
        load_peer_actor(run, 24, 2)


def test_a_policy_file_carrying_code_is_refused_without_running_it(tmp_path):
    run, marker = _copy_run(tmp_path), tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (Path.touch, (marker,))

    arrays = dict(np.load(run / "policy.npz"))
    arrays["log_std"] = np.array([Payload()], dtype=object)
    np.savez(run / "policy.npz", **arrays)
    with pytest.raises(ConfigError, match="not a peer policy archive"):
        load_peer_actor(run, 24, 2)
    assert not marker.exists()


def test_a_policy_of_the_wrong_shape_is_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"layer0: expected a weight \[out, 30\]"):
        load_peer_actor(PEER_RUN, 30, 2)
    run = _copy_run(tmp_path)
    (run / "peer.json").write_text("{}")
    with pytest.raises(ConfigError, match=r"peer\.json: peer: missing library, algo"):
        read_peer(run)


def test_a_peer_run_is_evaluated_as_crllk_s_runs_are(tmp_path):
    run = _copy_run(tmp_path)
    sampled = evaluate_peer(run, episodes=3, seed=VALIDATION_SEED, name="val", num_envs=3)
    again = evaluate_peer(run, episodes=3, seed=VALIDATION_SEED, name="val2", num_envs=3)
    mean = evaluate_peer(run, episodes=3, seed=VALIDATION_SEED, deterministic=True,
                         name="val-mode", num_envs=3)
    assert json.loads((run / "val.json").read_text()) == sampled
    assert sampled["summary"] == again["summary"]  # the sampling is seeded
    assert sampled["source"]["algo"] == "omnisafe-PPOLag"
    assert sampled["evaluation"] == {"episodes": 3, "seed": VALIDATION_SEED, "num_envs": 3,
                                     "deterministic": False}
    assert len(sampled["episodes"]) == len(mean["episodes"]) == 3
    assert set(sampled["summary"]) == {"J_R", "J_clane", "J_coll", "episode_length",
                                       "satisfied"}


# ----- the table's arithmetic ----------------------------------------------------------------
def _row(frames: int, episodes: int, lane: float, coll: float) -> dict[str, str]:
    return {"frames": str(frames), "time_s": str(frames / 100), "episodes": str(episodes),
            "J_clane": str(lane), "J_coll": str(coll)}


def test_time_to_constraints_worked_numbers():
    rows = [_row(1000, 2, 0.9, 1.0), _row(2000, 0, math.nan, math.nan),
            _row(3000, 2, 0.3, 0.0), _row(4000, 2, 0.2, 0.0)]
    # window 4: at 3000 the last four episodes average lane 0.6 > 0.5; at 4000 the last two
    # rows (4 episodes) average 0.25 dm and 0 collisions
    assert time_to_constraints(rows, ALPHAS, window=4) == (4000, 40.0)
    # window 2: the row at 3000 alone holds
    assert time_to_constraints(rows, ALPHAS, window=2) == (3000, 30.0)
    assert time_to_constraints(rows, ALPHAS, window=10) is None
    # a collision rate of 0.03 over the window misses alpha_2 = 0.02
    assert time_to_constraints([_row(100, 100, 0.1, 0.03)], ALPHAS) is None


def _entry(lanes: list[float], colls: list[float], travel: float) -> dict:
    return {"J_clane": {"values": lanes}, "J_coll": {"values": colls},
            "J_R": {"mean": travel}}


def test_the_best_tracker_is_the_one_whose_worst_seed_is_furthest_inside():
    entries = {"A": _entry([0.30, 0.35], [0.010, 0.015], 2.7),   # worst 0.015/0.02 = 0.75
               "B": _entry([0.20, 0.25], [0.000, 0.030], 2.9),   # worst 0.03/0.02 = 1.5
               "C": _entry([0.30, 0.375], [0.000, 0.005], 2.5)}  # worst 0.375/0.5 = 0.75
    assert worst_ratio(entries["A"]) == pytest.approx(0.75)
    assert worst_ratio(entries["B"]) == pytest.approx(1.5)
    assert best_tracker(entries) == "A"  # tied with C at 0.75; A travels farther


def test_the_peers_experiment_refuses_pixels():
    done = subprocess.run([sys.executable, "-m", "crllk.experiments", "peers", "--obs",
                           "pixels", "--runs-root", "/tmp/none", "--results", "/tmp/none"],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    assert done.returncode == 2
    assert done.stderr.strip() == ("error: experiments: --obs: peers: the peer library's "
                                   "agents read state features only: give --obs state")
