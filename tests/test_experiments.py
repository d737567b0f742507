"""``python -m crllk.experiments`` at a tiny budget: every run trained, evaluated, the tables and
figures written from their JSON; a second invocation reuses the finished runs."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import TINY_EXPERIMENT

from crllk.experiments import AGENTS, PAPER_TABLE1, sweep_markdown, table_markdown
from crllk.experiments.runs import MODE_EVALUATION
from crllk.experiments.seeds import seed_cells, seeds_markdown, seeds_table, table_documents
from crllk.protocol import TEST_EVALUATION, TEST_SEED, VALIDATION_SEED
from crllk.training.runs import read_eval_json

REPO = Path(__file__).resolve().parents[1]


def test_table1_lists_every_agent_beside_the_paper(tiny_experiments):
    runs, results, _ = tiny_experiments
    document = json.loads((results / "table1.json").read_text())
    assert list(document["agents"]) == list(AGENTS)
    assert document["paper"]["CRLLK-D"]["J_clane"] == list(PAPER_TABLE1["CRLLK-D"]["J_clane"])
    for agent, entry in document["agents"].items():
        run = runs / "small_loop" / f"{agent}-a0.5-seed0"
        test = read_eval_json(run, TEST_EVALUATION)
        assert test["evaluation"]["seed"] == TEST_SEED
        assert entry["J_clane"]["values"] == [test["summary"]["J_clane"]]
        assert entry["frames"] == [16]
        # the deployed policy (a discrete agent's expected duties, a continuous agent's
        # expected action), played through the same test episodes
        mode = json.loads((run / f"{MODE_EVALUATION}.json").read_text())
        assert mode["evaluation"]["deterministic"] is True
        assert mode["evaluation"]["deployed"] == (
            "expected_duty" if agent.endswith("-D") else "expected_action")
        assert entry["mode"]["deployed"] == [mode["evaluation"]["deployed"]]
        assert mode["evaluation"]["seed"] == TEST_SEED
        assert entry["mode"]["J_coll"]["values"] == [mode["summary"]["J_coll"]]
    markdown = (results / "table1.md").read_text()
    assert markdown == table_markdown(document)
    assert "| J_coll, deployed policy |" in markdown
    assert "CRLLK-D's deployed policy (expected duties)" in markdown
    assert "CRLLK-C's deployed policy (expected action)" in markdown
    assert "a discrete agent's expected wheel duties" in markdown
    assert "a continuous agent's expected action" in markdown
    assert "Budget: 16 environment frames per run" in markdown
    assert "Observation: `pixels`" in markdown and "python -m crllk.experiments all" in markdown
    assert "| J_clane (paper) | 0.66 ± 0.02 | 0.99 ± 0.07 | 0.31 ± 0.00 | 1.04 ± 0.25 | |" \
        in markdown
    assert "CRLLK-D misses" in markdown or "CRLLK-D satisfies" in markdown


def test_map_tables_and_figure1_are_written(tiny_experiments):
    runs, results, _ = tiny_experiments
    for task in ("zigzag", "obstacle_loop"):
        document = json.loads((results / f"table_{task}.json").read_text())
        assert list(document["agents"]) == list(AGENTS) and document["task"] == task
    figure = json.loads((results / "figure1.json").read_text())
    assert list(figure["thresholds"]) == ["0.08", "0.12", "0.2", "0.5"]
    for entry in figure["thresholds"].values():
        assert entry["curves"]["lambda_lane"]["frames"] == [16.0]  # one 16-frame iteration
        assert sum(entry["test_episode"]["actions"].values()) > 0
    for name in ("figure1_curves.png", "figure1_actions.png", "figure1_tradeoff.png"):
        assert (results / name).read_bytes()[:4] == b"\x89PNG"
    assert len(figure["thresholds"]["0.08"]["mode_evaluations"]) == 1
    words = (results / "figure1.md").read_text()
    assert figure["thresholds"]["0.08"]["deployed"] == ["expected_duty"]
    assert words.count("\n| 0.") == 4 and "deployed policy (expected duties), per seed" in words
    assert (runs / "small_loop" / "CRLLK-D-a0.08-seed0" / "eval.json").exists()
    config = (runs / "small_loop" / "CRLLK-D-a0.08-seed0" / "config.yaml").read_text()
    assert "threshold: 0.08" in config


def test_figure1_tradeoff_sets_crllk_against_the_sweep():
    """Each α1's seeds and mean, and every fixed-weight pair of the sweep's small_loop."""
    from crllk.analysis.figures import draw_figure1_tradeoff

    sweep = json.loads((REPO / "results/state/sweep.json").read_text())
    data = {"thresholds": {"0.1": {"evaluations": [{"J_clane": 0.09, "J_R": 2.5},
                                                   {"J_clane": 0.11, "J_R": 2.6}]},
                           "0.5": {"evaluations": [{"J_clane": 0.2, "J_R": 2.8}]}}}
    figure = draw_figure1_tradeoff(data, sweep)
    ax = figure.axes[0]
    fixed = len(sweep["maps"]["small_loop"]["fixed"])
    assert len(ax.collections) == fixed + 2 * 2 + 1  # the legend's grey marker too
    stars = [c.get_offsets().tolist() for c in ax.collections[fixed:]]
    assert [[0.1, 2.55]] in [[[round(x, 6), round(y, 6)] for x, y in o] for o in stars]
    assert [line.get_xdata()[0] for line in ax.lines] == [0.1, 0.5]
    assert len(draw_figure1_tradeoff(data, None).axes[0].collections) == 4


def _pair(lane_weight: float, lane: list[float], coll: list[float], travel: float) -> dict:
    return {"lane_weight": lane_weight, "collision_weight": 4.0, "J_clane": {
        "mean": sum(lane) / len(lane), "values": lane}, "J_coll": {"values": coll},
        "J_R": {"mean": travel}}


def test_figure1_words_compare_with_the_farthest_fixed_pair_holding_on_every_seed():
    """At α1 = 0.1 the 0.3 pair misses on one seed (0.12 dm) and the 10 pair collides, so the
    1 pair (2.60 m) is the one to beat: CRLLK-D's 2.55 m is 0.05 m short."""
    from crllk.experiments.figure1 import best_fixed_pair, figure1_markdown

    fixed = [_pair(0.3, [0.08, 0.12], [0.0, 0.0], 2.78), _pair(1, [0.07, 0.09], [0.0, 0.01], 2.60),
             _pair(3, [0.07, 0.07], [0.0, 0.0], 2.50), _pair(10, [0.06, 0.06], [0.0, 0.03], 2.70)]
    assert best_fixed_pair(fixed, 0.1, 0.02)["lane_weight"] == 1
    assert best_fixed_pair(fixed, 0.065, 0.02) is None
    summary = {"J_clane": 0.09, "J_coll": 0.0, "J_R": 2.5}
    data = {"settings": {"obs": "pixels", "episodes": 400, "seeds": [0, 1], "command": "c",
                         "frames": 10, "machine": "m"},
            "thresholds": {"0.1": {"evaluations": [summary, {**summary, "J_R": 2.6}],
                                   "mode_evaluations": [{**summary, "J_clane": 0.11}],
                                   "final_lambda_lane": [0.5, 0.25]}}}
    words = figure1_markdown(data, {"thresholds": {"collision": 0.02},
                                    "maps": {"small_loop": {"fixed": fixed}}})
    assert "| 0.1 | 0.090 / 0.000 / 2.50; 0.090 / 0.000 / 2.60 | 0.110 / 0.000 / 2.50 | " \
           "0.500, 0.250 | 1/4: 0.080 / 2.60 |" in words
    assert ("α1 = 0.1: the sampled policy holds both constraints on every seed (J_clane 0.090 "
            "dm, J_R 2.55 m), -0.05 m against the best fixed pair that holds (1/4); the "
            "deployed mode misses (J_clane 0.110 dm).") in words
    data["thresholds"]["0.1"]["deployed"] = ["expected_duty"]
    assert "the deployed policy (expected duties) misses" in figure1_markdown(data, None)


def test_deployed_label_names_what_the_evaluations_played():
    """Aggregates written before evaluations recorded how the deployed policy acted are the
    mode; all expected duties, all expected actions, or a mix, say so; the note names a
    continuous agent's expected action only where its evaluations played it."""
    from crllk.experiments.runs import deployed_label, deployed_note, mode_aggregate

    old, duties, mode = {"J_coll": {}}, {"deployed": ["expected_duty"]}, {"deployed": ["mode"]}
    action = {"deployed": ["expected_action"]}
    assert deployed_label([old, None]) == deployed_label([mode]) == "deployed policy (mode)"
    assert deployed_label([duties, None]) == "deployed policy (expected duties)"
    assert deployed_label([action]) == "deployed policy (expected action)"
    assert deployed_label([duties, mode]) == deployed_label([duties, action]) == \
        "deployed policy"
    assert deployed_note([duties, mode]).endswith("a continuous agent's mode")
    assert "a continuous agent's expected action (the mean of its tanh-squashed" in \
        deployed_note([duties, action, None])
    assert deployed_note([duties, action]).endswith("Gaussian's actions)")
    assert deployed_note([action, mode]).endswith(
        "or its mode in the evaluations that predate it")
    summary = {"J_R": 2.0, "J_clane": 0.1, "J_coll": 0.0, "episode_length": 512,
               "satisfied": True}
    documents = [{"source": {"run_dir": "a"}, "summary": summary,
                  "evaluation": {"deployed": "expected_duty"}},
                 {"source": {"run_dir": "b"}, "summary": summary, "evaluation": {}}]
    assert mode_aggregate(documents)["deployed"] == ["expected_duty", "mode"]


def test_every_seed_is_written_beside_the_tables(tiny_experiments):
    """seeds.md holds a row per agent and seed, a column per map, from the tables' JSON."""
    runs, results, _ = tiny_experiments
    documents = table_documents(results)
    assert list(documents) == ["table1", "table_zigzag", "table_obstacle_loop"]
    markdown = (results / "seeds.md").read_text()
    assert markdown == seeds_markdown(documents)
    assert "| agent, seed | small_loop | zigzag | obstacle_loop |" in markdown
    summary = read_eval_json(runs / "zigzag" / "PPO-C-a0.5-seed0", TEST_EVALUATION)["summary"]
    row = next(line for line in markdown.splitlines() if line.startswith("| PPO-C seed 0 |"))
    cell = row.split(" | ")[2]  # zigzag's: each constraint's number, then its interval
    assert re.sub(r" \([^)]*\)", "", cell).startswith(
        f"{summary['J_clane']:.3f} / {summary['J_coll']:.2f} / {summary['J_R']:.2f} ")
    assert cell.count("–") == 2
    assert "## The deployed policy" in markdown


def _entry(runs, clane, coll, travel, satisfied):
    return {"runs": runs, "J_clane": {"values": clane}, "J_coll": {"values": coll},
            "J_R": {"values": travel}, "satisfied": satisfied}


def test_seed_cells_and_table_worked_example():
    entry = _entry(["r/CRLLK-D-a0.5-seed1", "r/CRLLK-D-a0.5-seed0"], [0.4, 0.1234], [0.03, 0.0],
                   [2.694, 2.8], [False, True])
    assert seed_cells(entry) == {1: "0.400 / 0.03 / 2.69 ✗", 0: "0.123 / 0.00 / 2.80 ✓"}
    thresholds = {"lane": 0.5, "collision": 0.02}
    documents = {"table1": {"task": "small_loop", "agents": {"CRLLK-D": entry},
                            "thresholds": thresholds},
                 "table_zigzag": {"task": "zigzag", "thresholds": thresholds, "agents": {
                     "PPO-D": _entry(["r/PPO-D-a0.5-seed0"], [0.1], [0.0], [2.0], [True])}}}
    assert seeds_table(documents) == [
        "| agent, seed | small_loop | zigzag |",
        "| --- | --- | --- |",
        "| CRLLK-D seed 0 | 0.123 / 0.00 / 2.80 ✓ | — |",
        "| CRLLK-D seed 1 | 0.400 / 0.03 / 2.69 ✗ | — |",
        "| PPO-D seed 0 | — | 0.100 / 0.00 / 2.00 ✓ |"]
    assert seeds_table(documents, mode=True) == ["| agent, seed | small_loop | zigzag |",
                                                  "| --- | --- | --- |"]
    with pytest.raises(ValueError, match="does not end in -seed"):
        seed_cells(_entry(["r/CRLLK-D"], [0.1], [0.0], [2.0], [True]))


def test_seed_cells_judge_the_upper_bound_too():
    """With intervals and thresholds a second mark judges the 95 % upper bounds: seed 2's
    J_coll 0.015 holds (≤ 0.02) but its interval reaches 0.034."""
    entry = _entry(["r/X-seed0", "r/X-seed1", "r/X-seed2"], [0.1, 0.4, 0.2], [0.0, 0.03, 0.015],
                   [2.0, 2.0, 2.0], [True, False, True])
    entry["constraints"] = [{"name": "lane", "metric": "J_clane"},
                            {"name": "collision", "metric": "J_coll"}]
    entry["intervals"] = {"J_clane": [[0.08, 0.12], [0.35, 0.45], [0.15, 0.25]],
                          "J_coll": [[0.0, 0.01], [0.01, 0.06], [0.006, 0.034]]}
    cells = seed_cells(entry, {"lane": 0.5, "collision": 0.02})
    assert cells == {0: "0.100 (0.08–0.12) / 0.00 (0.00–0.01) / 2.00 ✓ ✓",
                     1: "0.400 (0.35–0.45) / 0.03 (0.01–0.06) / 2.00 ✗ ✗",
                     2: "0.200 (0.15–0.25) / 0.01 (0.01–0.03) / 2.00 ✓ ✗"}
    assert seed_cells(entry)[2].endswith("2.00 ✓")  # no thresholds: the point estimate only


def test_direction_cells_worked_example():
    """The episodes of each start direction judged apart: 3 of 100 intended episodes end on a
    collision (0.03 > 0.02), none of the reverse ones."""
    from crllk.evaluation.report import direction_results
    from crllk.experiments.seeds import direction_cells

    rows = [{"direction": "intended", "cost_lane": 0.4, "cost_collision": float(k < 3)}
            for k in range(100)] + [{"direction": "reverse", "cost_lane": 0.1,
                                     "cost_collision": 0.0}] * 100
    document = {"episodes": rows, "constraints": [
        {"name": "lane", "metric": "J_clane"}, {"name": "collision", "metric": "J_coll"}]}
    result = direction_results(document)
    assert result["intended"]["episodes"] == 100 and result["intended"]["J_coll"] == 0.03
    low, high = result["intended"]["J_coll_interval"]
    assert 0.010 < low < 0.011 and 0.084 < high < 0.085  # Wilson's, 3 of 100
    entry = {"runs": ["r/X-seed4"], "by_direction": [result],
             "constraints": document["constraints"]}
    cells = direction_cells(entry, {"lane": 0.5, "collision": 0.02})
    assert cells[4, "intended"] == "100 episodes: 0.400 (0.40–0.40) / 0.03 (0.01–0.08) ✗ ✗"
    assert cells[4, "reverse"] == "100 episodes: 0.100 (0.10–0.10) / 0.00 (0.00–0.04) ✓ ✗"


def test_tables_of_other_settings_leave_seeds_md_alone(tmp_path, capsys):
    """A table evaluated with other episodes than the others: a one-line warning, no
    seeds.md, no traceback."""
    from crllk.experiments.seeds import write_seeds

    entry = _entry(["r/CRLLK-D-a0.5-seed0"], [0.1], [0.0], [2.0], [True])
    for name, task, episodes in (("table1", "small_loop", 100), ("table_zigzag", "zigzag", 50)):
        document = {"task": task, "agents": {"CRLLK-D": entry}, "thresholds": {"lane": 0.5},
                    "settings": {"episodes": episodes, "eval_seed": 1, "obs": "pixels"}}
        (tmp_path / f"{name}.json").write_text(json.dumps(document))
    assert write_seeds(tmp_path) is None and not (tmp_path / "seeds.md").exists()
    warning = capsys.readouterr().err.strip().splitlines()
    assert len(warning) == 1 and "table_zigzag.json was evaluated with other" in warning[0]


def test_a_second_invocation_reuses_finished_runs(tiny_experiments, tmp_path):
    """The table says what its invocation did: the first trained its four runs, the second
    trained and evaluated nothing."""
    runs, results, _ = tiny_experiments
    first = json.loads((results / "table1.json").read_text())
    assert (first["runs_trained"], first["runs_total"]) == (4, 4)
    completed = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "table1", *TINY_EXPERIMENT, "--runs-root",
         str(runs.parent), "--results", str(tmp_path)], cwd=REPO, capture_output=True,
        text=True, timeout=300)
    assert completed.returncode == 0, completed.stderr
    assert "training 0 of 4 runs" in completed.stdout
    assert "test evaluation of 0 of 4 runs" in completed.stdout
    second = json.loads((tmp_path / "pixels" / "table1.json").read_text())
    assert (second["runs_trained"], second["evaluations_made"]) == (0, 0)
    assert second["agents"] == first["agents"]
    assert "which trained 0 of 4 runs and made 0 evaluations" in \
        (tmp_path / "pixels" / "table1.md").read_text()


def test_agents_choose_the_columns(tiny_experiments, tmp_path):
    """--agents trains and tabulates only those agents (here reusing the finished runs)."""
    runs, _, _ = tiny_experiments
    completed = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "table1", *TINY_EXPERIMENT, "--agents",
         "CRLLK-D", "CRLLK-C", "--runs-root", str(runs.parent), "--results", str(tmp_path)],
        cwd=REPO, capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stderr
    assert "training 0 of 2 runs" in completed.stdout
    document = json.loads((tmp_path / "pixels" / "table1.json").read_text())
    assert list(document["agents"]) == ["CRLLK-D", "CRLLK-C"] and document["pairs"] == []
    rejected = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "table1", "--agents", "SAC"], cwd=REPO,
        capture_output=True, text=True, timeout=60)
    assert rejected.returncode == 2 and "invalid choice: 'SAC'" in rejected.stderr


def test_runs_validate_on_the_validation_seed_and_the_tables_test_on_the_test_seed(
        tiny_experiments):
    """The trainer's evaluations (eval.csv, eval.json) use the validation seed; each finished
    run is evaluated once more on the test seed, sampled and mode, and only that is tabulated."""
    runs, _, stdout = tiny_experiments
    assert "test evaluation of 4 of 4 runs, and of the deployed policy of 4" in stdout
    run = runs / "small_loop" / "CRLLK-D-a0.5-seed0"
    assert read_eval_json(run)["evaluation"] == {"episodes": 2, "seed": VALIDATION_SEED,
                                                 "num_envs": 10, "deterministic": False}
    assert read_eval_json(run, TEST_EVALUATION)["evaluation"] == {
        "episodes": 2, "seed": TEST_SEED, "num_envs": 10, "deterministic": False}
    assert "1000000" in (run / "config.yaml").read_text()
    assert str(TEST_SEED) not in (run / "config.yaml").read_text()
    assert str(TEST_SEED) not in (run / "eval.csv").read_text()


def test_sweep_of_fixed_weights(tmp_path):
    """A 1 × 2 weight grid on one map from state: the JSON holds every pair and CRLLK-D, the
    Markdown is rebuilt from it, the figure is a PNG."""
    completed = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "sweep", *TINY_EXPERIMENT, "--obs", "state",
         "--sweep-tasks", "zigzag", "--lane-weights", "1", "--collision-weights", "4", "16",
         "--runs-root", str(tmp_path / "runs"), "--results", str(tmp_path / "results")],
        cwd=REPO, capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
    results = tmp_path / "results" / "state"
    document = json.loads((results / "sweep.json").read_text())
    entry = document["maps"]["zigzag"]
    assert [(e["lane_weight"], e["collision_weight"]) for e in entry["fixed"]] == [(1.0, 4.0),
                                                                                  (1.0, 16.0)]
    assert entry["crllk"]["agent"] == "CRLLK-D"
    assert (results / "sweep.md").read_text() == sweep_markdown(document)
    assert (results / "sweep.png").read_bytes()[:4] == b"\x89PNG"
    run = tmp_path / "runs" / "state" / "zigzag" / "PPO-D-w1-16-a0.5-seed0"
    assert read_eval_json(run)["source"]["multipliers"]["collision"] == 16.0


def test_a_finished_run_without_its_checkpoint_is_reused(tiny_experiments, tmp_path):
    """results/runs keeps runs with their policy but without checkpoints: such a run counts as
    trained to its policy's frames, its evaluation as current, and it can be evaluated again;
    without the policy too, the frames of its eval.json count."""
    import shutil

    from crllk import export
    from crllk.evaluation.runs import evaluate_run
    from crllk.experiments.runs import Settings, evaluation_is_current, trained_frames
    from crllk.training.runs import POLICY_FILE, load_run_policy

    runs, _, _ = tiny_experiments
    run = runs / "small_loop" / "CRLLK-D-a0.5-seed0"
    kept = tmp_path / "kept"
    shutil.copytree(run, kept)
    shutil.rmtree(kept / "checkpoints")
    assert (kept / POLICY_FILE).stat().st_size < 2_000_000
    assert trained_frames(kept) == 16
    assert evaluation_is_current(kept, Settings(frames=16, episodes=2), TEST_EVALUATION)
    again = evaluate_run(kept, episodes=2, seed=TEST_SEED, name="again")
    assert again["summary"] == read_eval_json(run, TEST_EVALUATION)["summary"]
    assert load_run_policy(kept).keys() == {"format", "iteration", "frames", "elapsed", "actor",
                                            "multipliers"}
    assert export.main([f"run={kept}", f"out={tmp_path / 'kept.onnx'}"]) == 0
    assert (tmp_path / "kept.onnx").stat().st_size > 0
    (kept / POLICY_FILE).unlink()
    assert trained_frames(kept) == 16  # from eval.json
    assert evaluation_is_current(kept, Settings(frames=16, episodes=2), TEST_EVALUATION)
    assert trained_frames(tmp_path / "nothing") == 0


def test_a_mode_evaluated_before_the_expected_forms_is_not_current(tiny_experiments,
                                                                  tmp_path):
    """The deployed policy of a discrete run is its expected duties, of a continuous run its
    expected action: a test-mode evaluation written before (the argmax or tanh of the mean,
    no ``deployed`` in its settings) is evaluated again."""
    import shutil

    from crllk.experiments.runs import Settings, evaluation_is_current

    runs, _, _ = tiny_experiments
    settings = Settings(frames=16, episodes=2)
    for agent in ("CRLLK-D", "CRLLK-C"):
        kept = tmp_path / agent
        shutil.copytree(runs / "small_loop" / f"{agent}-a0.5-seed0", kept)
        assert evaluation_is_current(kept, settings, MODE_EVALUATION, deterministic=True)
        path = kept / f"{MODE_EVALUATION}.json"
        document = json.loads(path.read_text())
        for old in ("mode", None):  # said so, or said nothing
            if old is None:
                del document["evaluation"]["deployed"]
            else:
                document["evaluation"]["deployed"] = old
            path.write_text(json.dumps(document))
            assert not evaluation_is_current(kept, settings, MODE_EVALUATION,
                                             deterministic=True)


def test_a_run_trained_before_policy_files_gets_one_from_its_checkpoint(tiny_experiments,
                                                                         tmp_path):
    import shutil

    import torch

    from crllk.training.runs import CHECKPOINT_FILE, POLICY_FILE, keep_policy, load_run_policy

    runs, _, _ = tiny_experiments
    old = tmp_path / "old"
    shutil.copytree(runs / "small_loop" / "CRLLK-C-a0.5-seed0", old)
    (old / POLICY_FILE).unlink()
    assert keep_policy(old) == old / POLICY_FILE
    checkpoint = torch.load(old / CHECKPOINT_FILE, weights_only=False)
    shutil.rmtree(old / "checkpoints")
    kept = load_run_policy(old)
    assert kept["frames"] == checkpoint["frames"] == 16
    for name, tensor in checkpoint["actor"].items():
        assert torch.equal(kept["actor"][name], tensor)
    assert keep_policy(old) is None  # nothing to keep it from


def test_a_run_kept_without_its_policy_is_trained_again_when_its_policy_is_needed(
        tiny_experiments, tmp_path, capsys):
    """A finished run kept with neither checkpoint nor policy.pt counts as trained, unless an
    experiment needs its policy (the robustness evaluations): then it is trained again."""
    import shutil

    from crllk.experiments.runs import RunSpec, Settings, train_and_evaluate, trained_frames
    from crllk.training.runs import POLICY_FILE, has_policy

    runs, _, _ = tiny_experiments
    root = tmp_path / "pixels"
    spec = RunSpec("CRLLK-D", "small_loop", 0)
    shutil.copytree(runs / "small_loop" / "CRLLK-D-a0.5-seed0", spec.directory(root))
    shutil.rmtree(spec.directory(root) / "checkpoints")
    (spec.directory(root) / POLICY_FILE).unlink()
    settings = Settings(frames=16, seeds=(0,), episodes=2, jobs=1, runs_root=root,
                        train_overrides=tuple(TINY_EXPERIMENT[TINY_EXPERIMENT.index("--set")
                                                               + 1:]))
    train_and_evaluate([spec], settings)
    assert "training 0 of 1 runs" in capsys.readouterr().out
    assert not has_policy(spec.directory(root)) and trained_frames(spec.directory(root)) == 16
    train_and_evaluate([spec], settings, policies=[spec])
    assert "training 1 of 1 runs" in capsys.readouterr().out
    assert has_policy(spec.directory(root))


@pytest.mark.slow
def test_robustness_at_a_tiny_budget(tmp_path):
    """``experiments robustness``: CRLLK-D trained without and with randomisation, each
    evaluated under the chosen conditions into ``robust-<condition>.json``; a table, its JSON
    and a figure; a second call reuses every run and evaluation."""
    runs, results = tmp_path / "runs", tmp_path / "results"
    argv = [sys.executable, "-m", "crllk.experiments", "robustness", *TINY_EXPERIMENT,
            "--robust-tasks", "small_loop", "--conditions", "nominal", "trim", "deployment",
            "--runs-root", str(runs), "--results", str(results)]
    done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    run = runs / "pixels" / "small_loop" / "CRLLK-D-rand-a0.5-seed0"
    assert "randomize: default" in (run / "config.yaml").read_text()
    for condition in ("nominal", "trim", "deployment"):
        document = json.loads((run / f"robust-{condition}.json").read_text())
        assert document["evaluation"]["episodes"] == 2
    assert json.loads((run / "robust-deployment.json").read_text())["evaluation"][
        "task_overrides"] == {"camera": {"robot_frames": True}}
    table = (results / "pixels" / "robustness.md").read_text()
    assert "| trim | randomized |" in table and "| deployment | nominal |" in table
    assert (results / "pixels" / "robustness.png").stat().st_size > 10_000
    again = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=900)
    assert again.returncode == 0 and "evaluating 0 of 6 run conditions" in again.stdout


def test_runs_become_as_few_trainer_sweeps_as_possible(tmp_path):
    """Every agent × map × seed of one setting is one multirun; an incomplete product is split
    by agent, then by map; the run directory interpolates the swept values."""
    from crllk.experiments import sweep_specs
    from crllk.experiments.runs import RunSpec, Settings, sweep_commands

    settings = Settings(runs_root=tmp_path, jobs=2)
    table1 = [RunSpec(a, "small_loop", s) for a in AGENTS for s in (0, 1)]
    (command,) = sweep_commands(table1, settings)
    assert command[2:5] == ["crllk.train", "-m", "agent=CRLLK-D,PPO-D,CRLLK-C,PPO-C"]
    assert {"task=small_loop", "seed=0,1", "hydra.launcher.n_jobs=2"} <= set(command)
    assert (f"run_dir={tmp_path}/${{task.name}}/${{hydra:runtime.choices.agent}}-a0.5"
            "-seed${seed}") in command
    partial = [RunSpec("CRLLK-D", "zigzag", 0), RunSpec("CRLLK-D", "zigzag", 1),
               RunSpec("CRLLK-D", "obstacle_loop", 1), RunSpec("PPO-D", "zigzag", 1)]
    swept = [[a for a in c if a.startswith(("agent=", "task=", "seed="))]
             for c in sweep_commands(partial, settings)]
    assert swept == [["agent=CRLLK-D", "task=zigzag", "seed=0,1"],
                     ["agent=CRLLK-D", "task=obstacle_loop", "seed=1"],
                     ["agent=PPO-D", "task=zigzag", "seed=1"]]
    grid = sweep_specs(Settings(seeds=(0, 1), lane_weights=(1.0,), collision_weights=(4.0,)))
    commands = sweep_commands(grid, settings)
    assert len(commands) == 2 and "task=small_loop,zigzag,obstacle_loop" in commands[1]
    assert any("-w1-4-a0.5-seed" in a for a in commands[1])


def test_a_table_from_a_sweep_run_by_hand(tmp_path):
    """A multirun started by hand into the experiments' layout is what ``crllk.experiments``
    reads: it trains nothing and writes the table from those runs."""
    runs = tmp_path / "runs"
    tiny = TINY_EXPERIMENT[TINY_EXPERIMENT.index("--set") + 1:]
    sweep = subprocess.run(
        [sys.executable, "-m", "crllk.train", "-m", "agent=CRLLK-D,PPO-D", "task=small_loop",
         "seed=0", "total_frames=16", "progress=false", "hydra.launcher.n_jobs=1", *tiny,
         f"run_dir={runs}/pixels/${{task.name}}/${{hydra:runtime.choices.agent}}-a0.5"
         "-seed${seed}"], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert sweep.returncode == 0, sweep.stderr[-2000:]
    table = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "table1", *TINY_EXPERIMENT, "--agents",
         "CRLLK-D", "PPO-D", "--runs-root", str(runs), "--results", str(tmp_path / "results")],
        cwd=REPO, capture_output=True, text=True, timeout=600)
    assert table.returncode == 0, table.stdout[-2000:] + table.stderr[-2000:]
    assert "training 0 of 2 runs" in table.stdout
    assert "test evaluation of 2 of 2 runs" in table.stdout  # once, on the test seed
    document = json.loads((tmp_path / "results" / "pixels" / "table1.json").read_text())
    assert list(document["agents"]) == ["CRLLK-D", "PPO-D"]


def test_teacher_ablation(tmp_path):
    """Three teacher variants on both maps from state at the tiny budget: every run trained
    with its overrides, tested on the test seed, and the Markdown rebuilt from the JSON."""
    from crllk.experiments.teacher import TEACHER_VARIANTS, teacher_markdown

    completed = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "teacher", *TINY_EXPERIMENT, "--obs",
         "state", "--runs-root", str(tmp_path / "runs"), "--results", str(tmp_path / "results")],
        cwd=REPO, capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
    results = tmp_path / "results" / "state"
    document = json.loads((results / "teacher.json").read_text())
    assert list(document["maps"]) == ["obstacle_loop", "small_loop"]
    for variants in document["maps"].values():
        assert list(variants) == list(TEACHER_VARIANTS)
        assert all("mode" in entry for entry in variants.values())
    assert (results / "teacher.md").read_text() == teacher_markdown(document)
    runs = tmp_path / "runs" / "state" / "small_loop"
    assert "coeff: 0.0" in (runs / "CRLLK-D-noteacher-a0.5-seed0" / "config.yaml").read_text()
    annealed = (runs / "CRLLK-D-teacher0-a0.5-seed0" / "config.yaml").read_text()
    assert "final: 0.0" in annealed and "frames: 400000" in annealed
    test = read_eval_json(runs / "CRLLK-D-teacher0-a0.5-seed0", TEST_EVALUATION)
    assert test["evaluation"]["seed"] == TEST_SEED


def test_crllk_agents_train_three_seeds_and_baselines_two():
    """The tables' claims about the CRLLK agents rest on three seeds; the text says which."""
    from crllk.experiments.runs import Settings, agent_seeds
    from crllk.experiments.tables import seeds_text

    settings = Settings()
    assert agent_seeds(settings, "CRLLK-C") == (0, 1, 2)
    assert agent_seeds(settings, "PPO-D") == (0, 1)
    document = {"seeds": [0, 1], "crllk_seeds": [0, 1, 2]}
    assert seeds_text(document, ["CRLLK-D", "PPO-D"]) == \
        "0, 1, 2 (CRLLK agents) and 0, 1 (fixed-weight baselines)"
    assert seeds_text(document, ["CRLLK-D"]) == "0, 1, 2"
    assert seeds_text(document, ["PPO-C"]) == "0, 1"
    assert seeds_text({"seeds": [3]}, ["CRLLK-D", "PPO-D"]) == "3"


def test_runs_on_map_files_sweep_apart_into_their_own_folders(tmp_path, monkeypatch):
    """A run on a map file lives in ``<runs-root>/<file stem>/``; its multirun passes
    ``task_file=`` (not ``task=``) and writes that folder out (the composed task name stays
    the default one), one file per sweep; named tasks sweep as before."""
    from crllk.experiments.realmaps import REAL_MAPS_DIR, realmaps_specs
    from crllk.experiments.runs import RunSpec, Settings, sweep_commands

    monkeypatch.chdir(REPO)
    settings = Settings(runs_root=tmp_path, jobs=2, seeds=(0, 1))
    specs = realmaps_specs(settings)
    assert [s.directory(tmp_path).relative_to(tmp_path).as_posix() for s in specs] == [
        "regress_4way_adam/CRLLK-D-a0.5-seed0", "regress_4way_adam/CRLLK-D-a0.5-seed1",
        "ETH_small_intersect/CRLLK-D-a0.5-seed0", "ETH_small_intersect/CRLLK-D-a0.5-seed1"]
    assert specs[0].task_file == "tests/data/real_maps/duckietown-world/regress_4way_adam.yaml"
    assert (REAL_MAPS_DIR / "ETH_small_intersect.yaml").is_file()
    named = RunSpec("CRLLK-D", "small_loop", 0)
    commands = sweep_commands([*specs, named], settings)
    assert len(commands) == 3
    for command, stem in zip(commands, ("regress_4way_adam", "ETH_small_intersect"),
                             strict=False):
        assert f"task_file=tests/data/real_maps/duckietown-world/{stem}.yaml" in command
        assert not any(a.startswith("task=") for a in command) and "seed=0,1" in command
        assert (f"run_dir={tmp_path}/{stem}/${{hydra:runtime.choices.agent}}-a0.5"
                "-seed${seed}") in command
    assert "task=small_loop" in commands[2] and "seed=0" in commands[2]
    assert f"run_dir={tmp_path}/${{task.name}}/${{hydra:runtime.choices.agent}}-a0.5" \
           "-seed${seed}" in commands[2]
    assert not any(a.startswith("task_file=") for a in commands[2])


def test_realmaps_refuses_task_overrides_a_map_file_does_not_take():
    from crllk.errors import ConfigError
    from crllk.experiments.realmaps import check_map_runs, realmaps_specs
    from crllk.experiments.runs import Settings

    settings = Settings(seeds=(0,), train_overrides=("task.horizon=12",))
    with pytest.raises(ConfigError, match=r"task\.horizon: a task file"):
        check_map_runs(realmaps_specs(settings), settings)


def _realmaps_entry(runs, clane, coll, intervals, terminations, hits):
    constraints = [{"name": "lane", "metric": "J_clane", "unit": "dm"},
                   {"name": "collision", "metric": "J_coll", "unit": "per episode"}]
    return {"runs": runs, "constraints": constraints,
            "J_clane": {"values": clane}, "J_coll": {"values": coll},
            "J_R": {"values": [2.5] * len(runs)},
            "satisfied": [a <= 0.5 and b <= 0.02 for a, b in zip(clane, coll, strict=True)],
            "intervals": intervals, "terminations": terminations, "collisions_by_object": hits}


def test_realmaps_markdown_worked_example():
    """Hand-made document: seed 1 misses J_coll by 0.010 and says how its episodes ended and
    what they hit; seed 0's mode holds on the point estimate but not at the upper bound; a map
    where everything holds says so."""
    from crllk.experiments.realmaps import realmaps_markdown

    runs = ["r/regress_4way_adam/CRLLK-D-a0.5-seed0", "r/regress_4way_adam/CRLLK-D-a0.5-seed1"]
    sampled = _realmaps_entry(
        runs, [0.312, 0.41], [0.0, 0.03],
        {"J_clane": [[0.29, 0.33], [0.38, 0.44]], "J_coll": [[0.0, 0.0095], [0.017, 0.051]]},
        [{"time_limit": 400}, {"time_limit": 388, "collision": 12}],
        [{}, {"14 barrier (1.60, 0.55)": 12}])
    sampled["mode"] = _realmaps_entry(
        runs, [0.2, 0.25], [0.01, 0.0],
        {"J_clane": [[0.18, 0.22], [0.23, 0.27]], "J_coll": [[0.004, 0.025], [0.0, 0.0095]]},
        [{"time_limit": 396, "off_road": 4}, {"time_limit": 400}], [{}, {}])
    eth = _realmaps_entry(["r/ETH_small_intersect/CRLLK-D-a0.5-seed0"], [0.2], [0.0],
                          {"J_clane": [[0.19, 0.21]], "J_coll": [[0.0, 0.0095]]},
                          [{"time_limit": 400}], [{}])
    document = {
        "title": "Maps nobody tuned on: CRLLK-D (pixels)",
        "thresholds": {"lane": 0.5, "collision": 0.02},
        "settings": {"obs": "pixels", "frames": 500_000, "episodes": 400,
                     "eval_seed": TEST_SEED, "command": "python -m crllk.experiments realmaps",
                     "machine": "2 CPU cores"},
        "wall_s": 60.0, "runs_total": 3, "runs_trained": 0, "evaluations_made": 0,
        "maps": {"regress_4way_adam": {"file": "m/regress_4way_adam.yaml",
                                       "about": "objects in the driving lane", **sampled},
                 "ETH_small_intersect": {"file": "m/ETH_small_intersect.yaml",
                                         "about": "intersections", **eth}}}
    text = realmaps_markdown(document)
    assert "## regress_4way_adam (`m/regress_4way_adam.yaml`)" in text
    assert ("| 1 | 0.410 (0.38–0.44) / 0.03 (0.02–0.05) / 2.50 ✗ ✗ | "
            "0.250 (0.23–0.27) / 0.00 (0.00–0.01) / 2.50 ✓ ✓ |") in text
    assert ("- seed 1, sampled policy: J_coll 0.030 over 0.02 by 0.010 (95 % upper bound "
            "0.051). Episodes ended: time_limit 388, collision 12. Objects hit (index, kind, "
            "position in m): 14 barrier (1.60, 0.55) ×12.") in text
    assert ("- seed 0, deployed policy (mode): J_coll 0.010 holds, its 95 % upper bound 0.025 "
            "over 0.02 by 0.005. Episodes ended: time_limit 396, off_road 4. Objects hit: "
            "none.") in text
    assert "seed 0, sampled policy" not in text and "seed 1, deployed" not in text
    eth_part = text.split("## ETH_small_intersect")[1]
    assert "| 0 | 0.200 (0.19–0.21) / 0.00 (0.00–0.01) / 2.50 ✓ ✓ | — |" in eth_part
    assert "Every run holds both constraints" in eth_part and "miss" not in eth_part


@pytest.mark.slow
def test_realmaps_at_a_tiny_budget(tmp_path):
    """``experiments realmaps`` end to end (60-80 s): both map files trained from pixels
    (the tiny budget without ``task.horizon``, which a map file refuses), tested on the test
    seed, the Markdown rebuilt from the JSON."""
    from crllk.experiments.realmaps import REALMAPS, realmaps_markdown

    tiny = [a for a in TINY_EXPERIMENT if not a.startswith("task.")]
    results = _run_tiny_experiment("realmaps", tiny, tmp_path)
    document = json.loads((results / "realmaps.json").read_text())
    assert list(document["maps"]) == list(REALMAPS)
    assert all("mode" in entry for entry in document["maps"].values())
    assert (results / "realmaps.md").read_text() == realmaps_markdown(document)
    run = tmp_path / "runs" / "pixels" / "regress_4way_adam" / "CRLLK-D-a0.5-seed0"
    assert "regress_4way_adam.yaml" in (run / "config.yaml").read_text()
    assert read_eval_json(run, TEST_EVALUATION)["evaluation"]["seed"] == TEST_SEED


def _run_tiny_experiment(name: str, arguments: list[str], tmp_path: Path) -> Path:
    """Runs ``python -m crllk.experiments <name>`` into ``tmp_path``; its results folder."""
    completed = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", name, *arguments,
         "--runs-root", str(tmp_path / "runs"), "--results", str(tmp_path / "results")],
        cwd=REPO, capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
    return tmp_path / "results" / "pixels"


@pytest.mark.slow
def test_traffic_at_a_tiny_budget(tmp_path):
    """``experiments traffic`` end to end: its agents trained from pixels on both traffic
    tasks, tested on the test seed with the community's metrics, the Markdown rebuilt from the
    JSON."""
    from crllk.experiments.traffic import TRAFFIC_TASKS, traffic_markdown

    results = _run_tiny_experiment("traffic", TINY_EXPERIMENT, tmp_path)
    document = json.loads((results / "traffic.json").read_text())
    assert list(document["tasks"]) == list(TRAFFIC_TASKS)
    for task, block in document["tasks"].items():
        assert list(block["agents"]) == ["CRLLK-D", "PPO-D", "CRLLK-C-stoppable"]
        for entry in block["agents"].values():
            assert "mode" in entry and entry["community"][0]["episodes"] == 2
        assert list(block["teacher"]) == ["discrete", "continuous", "stoppable"]
        assert block["teacher"]["discrete"]["community"][0]["episodes"] == 2
        metrics = [c["metric"] for c in block["agents"]["CRLLK-D"]["constraints"]]
        assert ("J_chead" in metrics) == (task == "traffic_loop")
    text = (results / "traffic.md").read_text()
    assert text == traffic_markdown(document)
    assert "| CRLLK-D | sampled | 0 |" in text and "| PPO-D | mode | 0 |" in text
    assert "| teacher | continuous | — |" in text and "| teacher | stoppable | — |" in text


def test_traffic_markdown_worked_example():
    """Every cell of a traffic table row from a hand-made document: the constraint with its
    interval and excess, the community medians, collisions by kind and multipliers."""
    from crllk.experiments.traffic import traffic_markdown

    constraints = [{"name": "lane", "metric": "J_clane", "unit": "dm"},
                   {"name": "collision", "metric": "J_coll", "unit": "per episode"},
                   {"name": "headway", "metric": "J_chead", "unit": "fraction of steps"}]
    entry = {"runs": ["r/traffic_loop/CRLLK-D-a0.5-seed1"], "constraints": constraints,
             "J_clane": {"values": [0.31]}, "J_coll": {"values": [0.05]},
             "J_chead": {"values": [0.02]}, "J_R": {"values": [4.5]},
             "intervals": {"J_clane": [[0.3, 0.32]], "J_coll": [[0.03, 0.08]],
                           "J_chead": [[0.01, 0.03]]},
             "community": [{"episodes": 400,
                            "survival_time_s": {"median": 17.07, "mean": 15.0},
                            "distance_tiles": {"median": 6.4, "mean": 6.0},
                            "lateral_deviation_m": {"median": 0.031, "mean": 0.03},
                            "outside_lane_s": {"median": 0.0, "mean": 0.2},
                            "collisions_by_kind": {"vehicle": 20}}],
             "multipliers": [{"lane": 0.0, "collision": 12.5, "headway": 0.5}]}
    document = {"title": "Lane keeping with traffic (pixels)",
                "settings": {"obs": "pixels", "frames": 500000, "episodes": 400,
                             "eval_seed": TEST_SEED, "machine": "2 cores",
                             "seeds": [0, 1], "crllk_seeds": [0, 1, 2],
                             "command": "python -m crllk.experiments traffic"},
                "trained": 0, "evaluated": 0, "wall_s": 1.0,
                "tasks": {"traffic_loop": {"about": "vehicles",
                                           "agents": {"CRLLK-D": entry, "PPO-D": entry},
                                           "thresholds": {"lane": 0.5, "collision": 0.02,
                                                          "headway": 0.05},
                                           "teacher": {"discrete": {
                                               **entry, "runs": ["teacher-seed0"],
                                               "multipliers": [{}]}}}}}
    text = traffic_markdown(document)
    assert "Constraints: J_clane ≤ 0.5 dm, J_coll ≤ 0.02 per episode, J_chead ≤ 0.05" in text
    assert "training seeds 0, 1, 2 (CRLLK agents) and 0, 1 (fixed-weight baselines)" in text
    assert ("| CRLLK-D | sampled | 1 | 0.310 (0.300–0.320) ✓ | 0.050 (0.030–0.080) ✗ +0.030 "
            "| 0.020 (0.010–0.030) ✓ | 4.50 | 17.1 | 6.40 | 0.031 | 0.00 | vehicle 20 "
            "| lane 0.00, collision 12.50, headway 0.50 |") in text
    assert ("| teacher | discrete | — | 0.310 (0.300–0.320) ✓ | 0.050 (0.030–0.080) ✗ +0.030 "
            "| 0.020 (0.010–0.030) ✓ | 4.50 | 17.1 | 6.40 | 0.031 | 0.00 | vehicle 20 | — |") \
        in text


def test_traffic_trains_its_agents_that_agents_keeps():
    """``traffic``: CRLLK-D and CRLLK-C on three seeds, PPO-D on two, on both tasks by default;
    ``--agents`` narrows them (PPO-C is not one of its agents)."""
    from crllk.experiments.runs import Settings
    from crllk.experiments.traffic import TRAFFIC_TASKS, traffic_specs

    every = traffic_specs(Settings())
    assert len(every) == (3 + 2 + 3) * len(TRAFFIC_TASKS)
    assert {s.agent for s in every} == {"CRLLK-D", "PPO-D", "CRLLK-C"}
    assert sorted(s.seed for s in every if s.agent == "PPO-D") == [0, 0, 1, 1]
    assert sorted(s.seed for s in every if s.agent == "CRLLK-C") == [0, 0, 1, 1, 2, 2]
    continuous = [s for s in every if s.agent == "CRLLK-C"]
    assert all(s.extra == ("action=stoppable",) for s in continuous)
    assert continuous[0].directory(Path("r")).name == "CRLLK-C-stoppable-a0.5-seed0"
    assert all(s.extra == () for s in every if s.agent != "CRLLK-C")
    narrowed = traffic_specs(Settings(seeds=(0,), crllk_seeds=(0,), agents=("CRLLK-D", "PPO-C")))
    assert [(s.agent, s.task) for s in narrowed] == [("CRLLK-D", t) for t in TRAFFIC_TASKS]


def test_fleet_at_a_tiny_budget(tmp_path):
    """``experiments fleet`` end to end: CRLLK-D and PPO-D trained from pixels on traffic_loop,
    tested alone and in a fleet of four robots (one fleet episode: as many robot-episodes as
    --episodes asks, at least one fleet episode), the Markdown rebuilt from the JSON."""
    from crllk.experiments.fleet import FLEET_AGENTS, FLEET_ROBOTS, fleet_markdown

    tiny = [*TINY_EXPERIMENT, "--agents", *FLEET_AGENTS]
    results = _run_tiny_experiment("fleet", tiny, tmp_path)
    document = json.loads((results / "fleet.json").read_text())
    assert list(document["agents"]) == list(FLEET_AGENTS)
    for block in document["agents"].values():
        assert block["alone"]["community"][0]["episodes"] == 2
        assert block["fleet"]["community"][0]["episodes"] == FLEET_ROBOTS
    text = (results / "fleet.md").read_text()
    assert text == fleet_markdown(document)
    assert "| CRLLK-D | alone | 0 |" in text and "| PPO-D | fleet | 0 |" in text
    assert document["evaluations_made"] >= 2 * len(FLEET_AGENTS)
    # the invocation's wall time counts its fleet evaluations, not only training and testing:
    # with only the fleet evaluations to make again it takes longer than with nothing to do
    fleet_files = sorted((tmp_path / "runs").rglob("test-fleet.json"))
    assert len(fleet_files) == document["runs_total"]
    for path in fleet_files:
        path.unlink()
    again = [json.loads((_run_tiny_experiment("fleet", tiny, tmp_path) / "fleet.json")
                        .read_text()) for _ in range(2)]
    assert [d["evaluations_made"] for d in again] == [len(fleet_files), 0]
    assert [d["runs_trained"] for d in again] == [0, 0]
    # a tiny fleet evaluation takes about a second on an idle machine: no margin is assumed
    assert again[0]["wall_s"] > again[1]["wall_s"]


def test_fleet_without_its_agents_fails_clearly(tmp_path):
    """``experiments fleet --agents CRLLK-C``: none of the fleet's agents, a one-line error."""
    completed = subprocess.run(
        [sys.executable, "-m", "crllk.experiments", "fleet", "--agents", "CRLLK-C",
         "--runs-root", str(tmp_path / "runs"), "--results", str(tmp_path / "results")],
        cwd=REPO, capture_output=True, text=True, timeout=300)
    assert completed.returncode == 2
    assert "--agents: fleet drives CRLLK-D or PPO-D" in completed.stderr
    assert "Traceback" not in completed.stderr


def test_fleet_markdown_worked_example():
    """A fleet table's rows from a hand-made document: the run alone and in the fleet, each
    robot's J_coll in the fleet row only."""
    from crllk.experiments.fleet import fleet_markdown

    constraints = [{"name": "lane", "metric": "J_clane", "unit": "dm"},
                   {"name": "collision", "metric": "J_coll", "unit": "per episode"}]

    def entry(j_coll: float, hits: dict) -> dict:
        return {"runs": ["r/traffic_loop/CRLLK-D-a0.5-seed2"], "constraints": constraints,
                "J_clane": {"values": [0.2]}, "J_coll": {"values": [j_coll]},
                "J_R": {"values": [4.0]},
                "community": [{"survival_time_s": {"median": 17.1}, "distance_tiles":
                               {"median": 6.4}, "lateral_deviation_m": {"median": 0.031},
                               "outside_lane_s": {"median": 0.0}, "collisions_by_kind": hits}],
                "multipliers": [{"lane": 0.0, "collision": 12.5}]}

    document = {"title": "Every robot driven by the policy (pixels)",
                "settings": {"obs": "pixels", "episodes": 400, "eval_seed": TEST_SEED,
                             "machine": "2 cores", "seeds": [0, 1], "crllk_seeds": [0, 1, 2],
                             "command": "python -m crllk.experiments fleet", "robots": 4,
                             "fleet_episodes": 100},
                "wall_s": 60.0, "task": "traffic_loop",
                "thresholds": {"lane": 0.5, "collision": 0.02},
                "agents": {"CRLLK-D": {"alone": entry(0.01, {}),
                                       "fleet": entry(0.05, {"vehicle": 20})}}}
    text = fleet_markdown(document)
    assert "100 fleet episodes of 4 robots (400 robot-episodes)" in text
    assert ("| CRLLK-D | alone | 2 | 0.200 ✓ | 0.010 ✓ | 4.00 | 17.1 | 6.40 | 0.031 | 0.00 "
            "| none |") in text
    assert ("| CRLLK-D | fleet | 2 | 0.200 ✓ | 0.050 ✗ +0.030 | 4.00 | 17.1 | 6.40 | 0.031 "
            "| 0.00 | vehicle 20 |") in text
