"""Evaluation of runs: eval.json against a hand-stepped rollout of the same seeds, the command,
aggregation across seeds and the lane follower's reference row."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_runs import run_in_process
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from crllk.envs.batched import make_env
from crllk.evaluation.report import aggregate
from crllk.evaluation.runs import evaluate_follower, evaluate_run
from crllk.training.runs import load_actor, read_eval_json

REPO = Path(__file__).resolve().parents[1]
EPISODES, NUM_ENVS, SEED = 5, 2, 7


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    return run_in_process(tmp_path_factory.mktemp("evaluate") / "run", 2, ["obs=state"])


@torch.no_grad()
def hand_rollout(run_dir: Path, episodes: int, num_envs: int, seed: int) -> list[dict]:
    """Steps the run's policy by hand, sampling from torch's generator seeded with ``seed``;
    episode k is sub-environment k mod N's (k // N)-th episode."""
    env = make_env("small_loop", num_envs=num_envs, observation="state", action="discrete",
                   seed=seed, overrides={"horizon": 12})
    actor, _ = load_actor(run_dir, env)
    sums = np.zeros((num_envs, 3))
    steps = np.zeros(num_envs, dtype=int)
    finished: list[list[dict]] = [[] for _ in range(num_envs)]
    td = env.reset()
    torch.manual_seed(seed)
    with set_exploration_type(ExplorationType.RANDOM):
        while min(len(f) for f in finished) < -(-episodes // num_envs):
            td = env.step(actor(td))
            nxt = td["next"]
            sums += torch.cat([nxt["reward"], nxt["cost_lane"], nxt["cost_collision"]],
                              -1).numpy()
            steps += 1
            for i in np.flatnonzero(nxt["done"].reshape(-1).numpy()):
                finished[i].append({"distance": sums[i, 0], "lane_cost": sums[i, 1] / steps[i],
                                    "collisions": sums[i, 2], "length": int(steps[i])})
                sums[i], steps[i] = 0.0, 0
            td = env.maybe_reset(step_mdp(td))
    env.close()
    return [finished[k % num_envs][k // num_envs] for k in range(episodes)]


def test_eval_json_matches_a_hand_rollout_of_the_same_seeds(tiny_run):
    document = evaluate_run(tiny_run, episodes=EPISODES, num_envs=NUM_ENVS, seed=SEED)
    assert read_eval_json(tiny_run) == json.loads(json.dumps(document))
    assert document["evaluation"] == {"episodes": EPISODES, "seed": SEED,
                                      "num_envs": NUM_ENVS, "deterministic": False}
    assert document["source"]["frames"] == 32 and document["source"]["obs"] == "state"
    rows = document["episodes"]
    assert [r["episode"] for r in rows] == list(range(EPISODES))
    expected = hand_rollout(tiny_run, EPISODES, NUM_ENVS, SEED)
    for row, hand in zip(rows, expected, strict=True):
        assert row["distance"] == pytest.approx(hand["distance"], abs=1e-5)
        assert row["cost_lane"] == pytest.approx(hand["lane_cost"], abs=1e-5)
        assert row["cost_collision"] == hand["collisions"]
        assert row["length"] == hand["length"]
        assert sum(row["actions"].values()) == row["length"]
        assert row["termination"] in ("off_road", "collision", "unstable", "time_limit")
    summary = document["summary"]
    assert summary["J_R"] == pytest.approx(np.mean([h["distance"] for h in expected]))
    assert summary["J_clane"] == pytest.approx(np.mean([h["lane_cost"] for h in expected]))
    assert summary["J_coll"] == pytest.approx(np.mean([h["collisions"] for h in expected]))
    histogram = document["action_histogram"]
    assert sum(histogram.values()) == pytest.approx(1.0)
    assert sum(document["terminations"].values()) == EPISODES
    assert summary["satisfied"] == (summary["J_clane"] <= 0.5 and summary["J_coll"] <= 0.02)


def test_sampled_evaluation_is_seeded(tiny_run):
    """Sampled evaluations of one seed agree action for action; the mode differs."""
    torch.manual_seed(123)  # whatever the global generator holds
    first = evaluate_run(tiny_run, episodes=4, num_envs=2, seed=3)
    second = evaluate_run(tiny_run, episodes=4, num_envs=2, seed=3)
    assert first["evaluation"]["deterministic"] is False
    assert [r["actions"] for r in first["episodes"]] == [r["actions"] for r in second["episodes"]]
    mode = evaluate_run(tiny_run, episodes=4, num_envs=2, seed=3, deterministic=True)
    assert mode["evaluation"]["deterministic"] is True
    assert mode["summary"] != first["summary"]


def test_a_discrete_run_deploys_its_expected_duties(tiny_run):
    """The tiny discrete run's deployed policy plays in a duty env: each command is its
    probabilities' mean of the three duty pairs; its evaluation says so, plays the same
    episodes again and histograms the wheel duties, all within the pairs' range."""
    from crllk.tasks.actions import DISCRETE_DUTIES
    from crllk.training.build import build_env
    from crllk.training.runs import load_run_config, played_action

    config = load_run_config(tiny_run)
    assert config.action.name == "discrete"
    assert played_action(config, False) == "discrete" and played_action(config, True) == "duty"
    env = build_env(config, num_envs=2, seed=3, action="duty")
    try:
        policy, _ = load_actor(tiny_run, env)
        td = policy(env.reset())
        duties = torch.tensor(DISCRETE_DUTIES, dtype=torch.float32)
        assert torch.allclose(td["action"], torch.softmax(td["logits"], -1) @ duties)
    finally:
        env.close()
    mode = evaluate_run(tiny_run, episodes=4, num_envs=2, seed=3, deterministic=True)
    again = evaluate_run(tiny_run, episodes=4, num_envs=2, seed=3, deterministic=True,
                         name="again")
    assert mode["evaluation"]["deployed"] == "expected_duty"
    assert again["episodes"] == mode["episodes"]
    histogram = mode["action_histogram"]
    assert DISCRETE_DUTIES.min() <= histogram["left_mean"] <= DISCRETE_DUTIES.max()
    assert sum(histogram["left"]) == sum(r["length"] for r in mode["episodes"])
    assert "actions" not in mode["episodes"][0]


def test_the_analyses_play_the_deployed_expected_duties(tiny_run):
    """The trajectory figure and the endings analysis play a discrete run's deployed policy in
    a duty env: every step's action is a duty pair within the three pairs' range."""
    from crllk.analysis.endings import play_endings
    from crllk.analysis.figures import policy_trajectory
    from crllk.tasks.actions import DISCRETE_DUTIES

    trajectory = policy_trajectory(tiny_run, seed=3, deterministic=True)
    actions = np.array(trajectory["actions"])
    assert actions.shape[1] == 2
    assert DISCRETE_DUTIES.min() - 1e-6 <= actions.min() <= actions.max() <= \
        DISCRETE_DUTIES.max() + 1e-6
    assert len(np.unique(actions.round(6), axis=0)) > 3  # not three pairs: their mixtures
    endings = play_endings(tiny_run, 2, 0.5, deterministic=True)
    assert endings["deterministic"] is True and endings["summary"]["episodes"] == 2


def test_aggregate_is_mean_and_population_std_across_runs():
    docs = [{"source": {"run_dir": name}, "summary": {"J_R": r, "J_clane": c, "J_coll": k,
                                                      "episode_length": 512,
                                                      "satisfied": c <= 0.5}}
            for name, r, c, k in (("a", 2.0, 0.3, 0.0), ("b", 3.0, 0.7, 0.1))]
    result = aggregate(docs)
    assert result["J_R"] == {"mean": 2.5, "std": 0.5, "values": [2.0, 3.0]}
    assert result["J_clane"]["mean"] == pytest.approx(0.5)
    assert result["J_clane"]["std"] == pytest.approx(0.2)
    assert result["J_coll"]["std"] == pytest.approx(0.05)
    assert result["satisfied"] == [True, False] and result["runs"] == ["a", "b"]


def test_the_lane_follower_is_a_reference_row():
    document = evaluate_follower("small_loop", episodes=2, num_envs=2, seed=11)
    assert document["source"]["algo"] == "follower"
    assert document["summary"]["J_coll"] == 0.0
    assert document["summary"]["J_clane"] < 0.5
    assert document["summary"]["J_R"] > 3.0  # about one lap of 5.9 m in 17 s
    assert set(document["action_histogram"]) >= {"left", "right", "bin_edges"}


def test_evaluate_command_writes_eval_json_and_aggregates(tiny_run, tmp_path):
    other = run_in_process(tmp_path / "other", 2, ["seed=1"])
    out = tmp_path / "both.json"
    result = subprocess.run(
        [sys.executable, "-m", "crllk.evaluate", f"runs=[{tiny_run},{other}]", "episodes=2",
         "num_envs=2", f"out={out}"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert "2 runs: J_R" in result.stdout
    both = json.loads(out.read_text())
    assert both["aggregate"]["runs"] == [str(tiny_run), str(other)]
    assert (other / "eval.json").exists()


@pytest.mark.parametrize(("args", "field"), [
    (["run=/no/such/run"], "run"),
    (["episodes=0", "follower=true"], "episodes"),
    (["episodes=many", "follower=true"], "episodes"),
    ([], "run"),
])
def test_bad_arguments_fail_clearly(args, field):
    result = subprocess.run([sys.executable, "-m", "crllk.evaluate", *args], cwd=REPO,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr.startswith(f"error: evaluate: {field}:")
    assert "Traceback" not in result.stderr


def test_a_directory_without_a_run_fails_clearly(tmp_path):
    result = subprocess.run([sys.executable, "-m", "crllk.evaluate", f"run={tmp_path}"],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert "not a run directory" in result.stderr and "Traceback" not in result.stderr


def test_a_pixel_run_with_state_critics_evaluates_and_draws(tmp_path):
    """Pixel policies whose critics read the state features rebuild their env with that state."""
    from crllk.analysis.figures import policy_trajectory

    run = run_in_process(tmp_path / "pixels", 1, ["obs=pixels", "model.critic_input=state"])
    document = evaluate_run(run, episodes=2, num_envs=2, seed=1)
    assert document["source"]["obs"] == "pixels" and len(document["episodes"]) == 2
    episode = policy_trajectory(run)
    assert len(episode["trail"]) == len(episode["lane_costs"]) + 1


def test_teacher_reference_passes_obstacles():
    """The swerving teacher through the evaluation: no collision in 6 short episodes of
    obstacle_loop where the plain follower collides."""
    teacher = evaluate_follower("obstacle_loop", episodes=6, num_envs=3, seed=1000000,
                                avoid_obstacles=True)
    assert teacher["source"]["algo"] == "teacher"
    assert teacher["summary"]["J_coll"] == 0.0


def test_help_prints_the_usage(capsys):
    from crllk import evaluate

    assert evaluate.main(["--help"]) == 0
    assert "python -m crllk.evaluate run=" in capsys.readouterr().out


def test_an_evaluation_under_changed_task_settings_goes_to_its_own_file(tmp_path):
    """``overrides.*`` change the run's task for one evaluation (here the deployment path of
    the camera and randomisation), written to ``<name>.json`` beside the nominal
    ``eval.json``, which it leaves alone; the document records the overrides."""
    run = run_in_process(tmp_path / "pixels", 1, ["obs=pixels", "eval.final=false"])
    nominal = evaluate_run(run, episodes=2, num_envs=2)
    changed = evaluate_run(run, episodes=2, num_envs=2, name="eval-robot-randomized",
                           overrides={"camera": {"robot_frames": True},
                                      "randomize": "default"})
    assert json.loads((run / "eval.json").read_text())["summary"] == nominal["summary"]
    assert json.loads((run / "eval-robot-randomized.json").read_text()) == changed
    assert changed["evaluation"]["task_overrides"] == {"camera": {"robot_frames": True},
                                                       "randomize": "default"}
    assert changed["episodes"] != nominal["episodes"]


def test_cost_critic_fit_over_whole_batches(tiny_run, tmp_path):
    """The cost-critic diagnostic restores the run, collects, and writes its JSON; bad input
    is one line."""
    import shutil

    from crllk.analysis import cost_critics

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    assert cost_critics.main([str(run), "--batches", "2"]) == 0
    fit = json.loads((run / "cost-critic-collision.json").read_text())
    assert fit["frames"] == 2 * 16 and fit["cost_steps"] >= 0 and fit["constraint"] == "collision"
    assert -1.0 <= fit["correlation"] <= 1.0 or np.isnan(fit["correlation"])
    assert sum(row["steps"] for row in fit["calibration"]) == fit["frames"]
    assert [(row["from"], row["to"]) for row in fit["lead"]] == [tuple(w) for w in
                                                                 cost_critics.LEAD_WINDOWS]
    for argv, message in (([str(tmp_path / "none")], "no such run directory"),
                          ([str(run), "--constraint", "speed"], "is not a constraint")):
        completed = subprocess.run([sys.executable, "-m", "crllk.analysis.cost_critics", *argv],
                                   capture_output=True, text=True, timeout=120)
        assert completed.returncode == 2 and message in completed.stderr
        assert len(completed.stderr.strip().splitlines()) == 1
