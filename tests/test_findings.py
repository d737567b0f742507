"""The figures ``docs/findings.md`` quotes from kept evaluations are those evaluations'."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from docs_pages import prose

from crllk.evaluation.intervals import wilson_interval
from crllk.protocol import TEST_SEED

REPO = Path(__file__).resolve().parents[1]
FINDINGS = (REPO / "docs/findings.md").read_text()


@pytest.mark.parametrize("margin", ["0.07", "0.04", "0.02"])
def test_the_teacher_margin_table_is_the_kept_evaluations(margin):
    path = REPO / f"results/scripted/teacher-obstacle_loop-margin{margin}.json"
    document = json.loads(path.read_text())["teacher"]
    assert document["evaluation"]["margin"] == float(margin)
    intended = document["breakdown"]["by_direction"]["intended"]
    row = (f"| {intended['J_clane']:.3f} | {intended['J_coll']:.3f} | "
           f"{document['summary']['J_clane']:.3f} |")
    assert any(line.startswith(f"| {margin}") and line.endswith(row)
               for line in FINDINGS.splitlines()), row


def test_the_default_command_s_directions_are_its_evaluation():
    run = REPO / "results/runs/pixels/obstacle_loop/default-command-alone"
    intended = json.loads((run / "eval.json").read_text())["breakdown"]["by_direction"][
        "intended"]
    text = " ".join(FINDINGS.split())
    assert (f"**{intended['J_clane']:.3f} dm** and {intended['J_coll']:.3f} over the "
            f"{intended['episodes']} intended episodes") in text


@pytest.mark.parametrize("seed", [0, 1])
def test_the_annealed_teacher_table_is_the_runs(seed):
    import csv

    run = REPO / f"results/runs/pixels/obstacle_loop/CRLLK-D-teacher0-curve1-a0.5-seed{seed}"
    with (run / "metrics.csv").open() as handle:
        rows = list(csv.DictReader(handle))

    def training_j_coll(low: int, high: int) -> float:
        values = [float(r["J_coll"]) for r in rows
                  if low <= int(r["frames"]) < high and r["J_coll"] not in ("nan", "")]
        return sum(values) / len(values)

    table = {line.split(" | ")[0].strip("| "): line.strip("|").split(" | ")[1:]
             for line in FINDINGS.splitlines() if line.startswith("| training J_coll")
             or line.startswith("| λ_coll at the end") or line.startswith("| validation J_coll")}
    column = seed
    assert table["training J_coll, frames 200k–350k (weight 0.5 → 0.13)"][column].strip() == \
        f"{training_j_coll(200_000, 350_000):.3f}"
    assert table["training J_coll, frames 400k–500k (weight 0)"][column].strip() == \
        f"{training_j_coll(400_000, 600_000):.3f}"
    multiplier = float(rows[-1]["lambda_collision"])
    assert table["λ_coll at the end"][column].strip() == f"{multiplier:.1f}"
    final = json.loads((run / "eval.json").read_text())["summary"]["J_coll"]
    assert table["validation J_coll at the end (100 episodes)"][column].strip() == f"{final:.2f}"


def test_the_collision_critic_traces_are_the_runs():
    import csv

    root = REPO / "results/runs/pixels/obstacle_loop"

    def mean(run: str, column: str, low: int, high: int) -> float:
        with (root / run / "metrics.csv").open() as f:
            values = [float(r[column]) for r in csv.DictReader(f)
                      if low <= int(r["frames"]) < high and r[column] not in ("nan", "")]
        return sum(values) / len(values)

    runs = ["CRLLK-D-teacher0-curve1-a0.5-seed0", "CRLLK-D-teacher0-curve1-a0.5-seed1"]
    straight = [f"{mean(r, 'action_straight', 200_000, 350_000):.2f} → "
                f"{mean(r, 'action_straight', 400_000, 600_000):.2f}" for r in runs]
    assert " | ".join(straight) in FINDINGS
    kl = [f"{mean(r, 'kl_approx', 200_000, 350_000):.4f} → "
          f"{mean(r, 'kl_approx', 450_000, 600_000):.4f}" for r in runs]
    assert " | ".join(kl) in FINDINGS
    for label, run in (("annealed, seed 0", runs[0]), ("annealed, seed 1", runs[1]),
                       ("default command (`default-command-alone`)", "default-command-alone")):
        fit = json.loads((root / run / "cost-critic-collision.json").read_text())
        assert fit["frames"] == 12_288
        assert (f"| {label} | {fit['cost_steps']} | {fit['explained_variance']:.3f} | "
                f"{fit['correlation']:.3f} |") in FINDINGS
    logged = [f"{mean(r, 'explained_variance_collision', 200_000, 350_000):.2f}"
              for r in [*runs, "default-command-alone"]]
    assert ", ".join(logged[:2]) + " and " + logged[2] in " ".join(FINDINGS.split())


@pytest.mark.parametrize("where", ["README.md", "index.md"])
def test_in_short_quotes_what_the_teacher_buys_on_the_test_seed(where):
    """The teacher's line is the teacher experiment's test evaluations
    (``results/pixels/teacher.json``): the annealed runs' sampled J_coll, and the sampled and
    deployed J_coll without a teacher and with the floor."""
    variants = json.loads((REPO / "results/pixels/teacher.json").read_text())["maps"][
        "obstacle_loop"]

    def both(name: str, policy: str | None = None) -> str:
        entry = variants[name] if policy is None else variants[name][policy]
        return " and ".join(f"{v:.2f}" for v in entry["J_coll"]["values"])

    text = " ".join(prose(where).split())
    floor = "floor 0.3 (default)"
    assert f"CRLLK-D collapses to J_coll {both('annealed to 0 by 400k frames')};" in text
    assert (f"its sampled policy collides {both('no teacher')} times per episode and its "
            f"expected duties {both('no teacher', 'mode')}, against {both(floor)} (sampled) "
            f"and {both(floor, 'mode')} (expected duties) with the floor") in text


@pytest.mark.parametrize("where", ["README.md", "index.md"])
def test_in_short_quotes_what_the_other_aids_buy(where):
    """The encounter spawns' and the state critics' lines are the aids experiment's test
    evaluations (``results/pixels/aids.json``)."""
    variants = json.loads((REPO / "results/pixels/aids.json").read_text())["maps"][
        "obstacle_loop"]

    def sampled(name: str) -> str:
        return " and ".join(f"{v:.2f}" for v in variants[name]["J_coll"]["values"])

    def worst_mode(name: str) -> str:
        return f"{max(variants[name]['mode']['J_coll']['values']):.2f}"

    text = " ".join(prose(where).split())
    assert (f"(J_coll {sampled('no encounter spawns')} without encounter spawns, "
            f"{sampled('pixel critics')} with pixel critics, against {sampled('default')} "
            "with both)") in text
    assert (f"(at worst {worst_mode('no encounter spawns')} and {worst_mode('pixel critics')} "
            f"per episode, against {worst_mode('default')})") in text


def test_the_annealed_small_loop_runs_are_quoted_as_they_ended():
    text = " ".join(FINDINGS.split())
    root = REPO / "results/runs/pixels/small_loop"
    seeds = [json.loads((root / f"CRLLK-D-teacher0-a0.5-seed{s}" / "eval.json").read_text())
             ["summary"] for s in (0, 1)]
    assert (f"seed 0 at J_clane {seeds[0]['J_clane']:.3f} dm and J_coll {seeds[0]['J_coll']:.2f}"
            f" (validation), seed 1 at {seeds[1]['J_clane']:.3f} dm and "
            f"{seeds[1]['J_coll']:.2f}") in text


TEACHER_VARIANTS = {"floor 0.3 (default)": "", "annealed to 0 by 400k frames": "-teacher0",
                    "no teacher": "-noteacher"}


@pytest.mark.parametrize("label", TEACHER_VARIANTS)
def test_the_teacher_choice_table_is_the_validation_evaluations(label):
    """The default was chosen on the validation seed: each cell is the runs' ``eval.json`` and
    ``eval-mode.json``, both on that seed."""
    from crllk.protocol import VALIDATION_SEED

    cells = []
    for task in ("obstacle_loop", "small_loop"):
        for seed in (0, 1):
            variant = TEACHER_VARIANTS[label] + ("-curve1" if task == "obstacle_loop" else "")
            run = REPO / f"results/runs/pixels/{task}/CRLLK-D{variant}-a0.5-seed{seed}"
            sampled, mode = (json.loads((run / f"{name}.json").read_text())
                             for name in ("eval", "eval-mode"))
            assert sampled["evaluation"]["seed"] == mode["evaluation"]["seed"] == VALIDATION_SEED
            assert mode["evaluation"]["deterministic"]
            assert not sampled["evaluation"]["deterministic"]
            cells.append("; ".join(f"{d['summary']['J_clane']:.3f} / {d['summary']['J_coll']:.2f}"
                                   for d in (sampled, mode)))
    assert f"| {label} | " + " | ".join(cells) + " |" in FINDINGS.splitlines()


def test_the_figure1_page_s_numbers_are_figure1_json():
    """Each threshold's mean J_clane and J_R, its final λ_lane per seed and its mode's J_clane,
    as the site's Figure 1 page quotes them."""
    readme = prose("results/figure1.md")
    figure = json.loads((REPO / "results/pixels/figure1.json").read_text())
    parts, modes = [], []
    for threshold, entry in figure["thresholds"].items():
        sampled, mode = entry["evaluations"], entry["mode_evaluations"]
        lane = sum(e["J_clane"] for e in sampled) / len(sampled)
        travel = sum(e["J_R"] for e in sampled) / len(sampled)
        lambdas = " / ".join(f"{v:.2f}" for v in entry["final_lambda_lane"])
        parts.append(f"{threshold} → {lane:.3f}, {travel:.2f}, {lambdas}")
        modes.append(f"{sum(e['J_clane'] for e in mode) / len(mode):.3f}")
    assert "; ".join(parts) + "." in readme
    assert f"J_clane {', '.join(modes[:-1])} and {modes[-1]} dm" in readme


def test_the_figure1_page_s_distance_to_the_best_fixed_pair_is_the_sweep_s():
    from crllk.experiments.figure1 import best_fixed_pair

    figure = json.loads((REPO / "results/pixels/figure1.json").read_text())
    sweep = json.loads((REPO / "results/pixels/sweep.json").read_text())
    fixed = sweep["maps"]["small_loop"]["fixed"]
    gaps = []
    for threshold, entry in figure["thresholds"].items():
        best = best_fixed_pair(fixed, float(threshold), sweep["thresholds"]["collision"])
        travel = sum(e["J_R"] for e in entry["evaluations"]) / len(entry["evaluations"])
        gaps.append(abs(travel - best["J_R"]["mean"]))
    assert f"within {max(gaps) + 0.005:.2f} m" in prose("results/figure1.md")


def _test_document(task: str, agent: str, seed: int, name: str = "test") -> dict:
    return json.loads((REPO / f"results/runs/pixels/{task}/{agent}-a0.5-seed{seed}/{name}.json")
                      .read_text())


CRLLK_SEEDS = {"CRLLK-D": (0, 1, 2), "CRLLK-C": (0, 1, 2)}


def test_the_obstacle_loop_figures_are_the_test_evaluations():
    """The prose of "In short" (the README, and the site's home page that includes it) and of
    the site's results from the camera: the sampled CRLLK-D's and PPO-D's J_coll, the final
    λ_coll, the deployed policies' J_coll over all episodes and in the blocked direction, the
    collisions with the curve duckie among all of the CRLLK runs' test collisions, and
    J_clane in the blocked direction, from the runs' ``test.json`` and ``test-mode.json``;
    the former default's runs and the replaced ones as quoted; the teacher said never to
    collide does not."""
    readme = " ".join((REPO / "README.md").read_text().split())
    home, camera = prose("index.md"), prose("results/camera.md")
    crllk = [_test_document("obstacle_loop", "CRLLK-D", s)["summary"]["J_coll"] for s in (0, 1, 2)]
    ppo = [_test_document("obstacle_loop", "PPO-D", s)["summary"]["J_coll"] for s in (0, 1)]
    lam = [_test_document("obstacle_loop", "CRLLK-D", s)["source"]["multipliers"]["collision"]
           for s in (0, 1, 2)]
    for agent, seeds in (("CRLLK-D", (0, 1, 2)), ("PPO-D", (0, 1))):
        for seed in seeds:
            config = (REPO / f"results/runs/pixels/obstacle_loop/{agent}-a0.5-seed{seed}/"
                      "config.yaml").read_text()
            assert "encounter_curve_weight: 4.0" in config
    hits = total = 0
    intended = []
    for agent, seeds in CRLLK_SEEDS.items():
        for seed in seeds:
            for name in ("test", "test-mode"):
                breakdown = _test_document("obstacle_loop", agent, seed, name)["breakdown"]
                objects = breakdown["collisions_by_object"]
                total += sum(objects.values())
                hits += objects.get("3 duckie (0.88, 0.88)", 0)
                intended.append(breakdown["by_direction"]["intended"]["J_clane"])
    spread = f"{min(intended):.2f}–{max(intended):.2f} dm"
    sampled = f"J_coll {crllk[0]:.3f}, {crllk[1]:.3f} and {crllk[2]:.3f}"
    for text in (readme, home):
        assert (f"the sampled CRLLK-D gives {sampled}, against {ppo[0]:.3f} and {ppo[1]:.3f} for "
                "the original's fixed weights") in text
        assert f"{hits} of the CRLLK runs' {total} test collisions are with one duckie" in text
        assert f"every CRLLK run deviates {spread}, over α1" in text
    assert all(j <= 0.02 for j in crllk) and all(j > 0.02 for j in ppo)
    assert f"{hits} of the {total} collisions of the CRLLK runs' test episodes" in camera
    assert (f"The sampled CRLLK-D gives {sampled} on seeds 0, 1 and 2 (its learned λ_coll ended "
            f"at {lam[0]:.1f}, {lam[1]:.1f} and {lam[2]:.1f}), where the original's fixed weight "
            f"of 4 gives PPO-D {ppo[0]:.3f} and {ppo[1]:.3f}") in camera
    assert f"J_clane is {spread} for every CRLLK run" in camera
    sampled_docs = [_test_document("obstacle_loop", "CRLLK-D", s) for s in (0, 1, 2)]
    deployed = [_test_document("obstacle_loop", "CRLLK-D", s, "test-mode") for s in (0, 1, 2)]
    assert all(d["evaluation"]["deployed"] == "expected_duty" for d in deployed)

    def upper(document: dict, direction: str | None = None) -> float:
        episodes = [e for e in document["episodes"]
                    if direction is None or e["direction"] == direction]
        return wilson_interval(sum(e["cost_collision"] > 0 for e in episodes),
                               len(episodes))[1]

    held = [d["summary"]["J_clane"] <= 0.5 and d["summary"]["J_coll"] <= 0.02 for d in deployed]
    assert all(held)
    sampled_upper = [s for s, d in enumerate(sampled_docs) if upper(d) <= 0.02]
    deployed_upper = [s for s, d in enumerate(deployed) if upper(d) <= 0.02]
    assert (f"at the 95 % upper bound on {_seeds_text(sampled_upper)}") in camera
    assert ("CRLLK-D's deployed policy, its expected wheel duties, holds both constraints on "
            f"every seed, at the 95 % upper bound on {_seeds_text(deployed_upper)}") in camera
    quoted = (f"J_coll {deployed[0]['summary']['J_coll']:.3f}, "
              f"{deployed[1]['summary']['J_coll']:.3f} and {deployed[2]['summary']['J_coll']:.3f}")
    for text in (readme, home, camera):
        assert quoted in text
    blocked = [d["breakdown"]["by_direction"]["intended"]["J_coll"] for d in deployed]
    assert all(b <= 0.02 for b in blocked)
    assert (f"in the blocked direction alone on the point estimate (J_coll {blocked[0]:.3f}, "
            f"{blocked[1]:.3f} and {blocked[2]:.3f};") in camera
    bounds = [upper(d, "intended") for d in deployed]
    count = sum(e["direction"] == "intended" for e in deployed[0]["episodes"])
    assert (f"the upper bounds there are {min(bounds):.3f}–{max(bounds):.3f}, "
            f"{count} episodes per run") in camera
    c_sampled = [_test_document("obstacle_loop", "CRLLK-C", s)["summary"]["J_coll"]
                 for s in (0, 1, 2)]
    c_mode = [_test_document("obstacle_loop", "CRLLK-C", s, "test-mode") for s in (0, 1, 2)]
    assert all(d["evaluation"]["deployed"] == "expected_action" for d in c_mode)
    assert [k for k, j in enumerate(c_sampled) if j > 0.02] == [0, 2]
    assert [k for k, d in enumerate(c_mode) if d["summary"]["J_coll"] > 0.02] == [2]
    assert [k for k, d in enumerate(c_mode) if upper(d) <= 0.02] == [1]
    c_deployed = [d["summary"]["J_coll"] for d in c_mode]
    for text in (readme, home):
        assert (f"sampled policy misses α2 on seeds 0 and 2 (J_coll {c_sampled[0]:.3f}, "
                f"{c_sampled[1]:.3f} and {c_sampled[2]:.3f} on seeds 0, 1 and 2)") in text
        assert (f"holds on seeds 0 and 1 (J_coll {c_deployed[0]:.3f} and {c_deployed[1]:.3f}) "
                f"but not on seed 2 ({c_deployed[2]:.3f})") in text
    assert all(d["summary"]["J_clane"] <= 0.5 for d in c_mode[:2])
    assert (f"CRLLK-C misses α2 sampled on seeds 0 and 2 (J_coll {c_sampled[0]:.3f}, "
            f"{c_sampled[1]:.3f} and {c_sampled[2]:.3f} on seeds 0, 1 and 2); its deployed "
            "policy, its expected "
            f"action, holds both constraints on seeds 0 and 1 (J_coll {c_deployed[0]:.3f} and "
            f"{c_deployed[1]:.3f}, at the 95 % upper bound on seed 1) and misses on seed 2 "
            f"({c_deployed[2]:.3f})") in camera
    c_lambdas = [d["source"]["multipliers"]["collision"] for d in c_mode]
    first_c2 = REPO / "results/runs/pixels/replaced/obstacle_loop/CRLLK-C-a0.5-seed2"
    trainings = [REPO / "results/runs/pixels/obstacle_loop/CRLLK-C-a0.5-seed2", first_c2]
    late = [_late_collisions(run) for run in trainings]
    ended = [_final_multiplier(run) for run in trainings]
    assert f"{ended[0]:.1f}" == f"{c_lambdas[2]:.1f}"
    assert (f"it ended with λ_coll {ended[0]:.1f} and {ended[1]:.1f} and its training episodes "
            f"still colliding {late[0]:.3f} and {late[1]:.3f} per episode over iterations "
            "400–489") in readme
    assert (f"its learned λ_coll ended at {c_lambdas[2]:.1f}, against {c_lambdas[0]:.1f} and "
            f"{c_lambdas[1]:.1f} for seeds 0 and 1, and its training episodes still collided "
            f"{late[0]:.3f} per episode over iterations 400–489") in camera
    findings = " ".join(FINDINGS.split())
    assert (f"the default's third seed, trained later for the test table, ended with σ "
            f"{_steering_scale(trainings[0]):.2f} and still collided {late[0]:.3f} per episode "
            "in training") in findings
    zigzag = [json.loads((REPO / f"results/runs/pixels/{where}/CRLLK-C-a0.5-seed2/test.json")
                         .read_text())["summary"]["J_coll"]
              for where in ("replaced/zigzag", "zigzag")]
    assert zigzag[0] > 0.02 >= zigzag[1]
    assert f"(J_coll {zigzag[0]:.3f} then, {zigzag[1]:.3f} now)" in camera
    assert f"the first seed 2 had missed α2 sampled, J_coll {zigzag[0]:.3f})" in readme
    first = [json.loads((first_c2 / f"{n}.json").read_text()) for n in ("test", "test-mode")]
    assert "deployed" not in first[1]["evaluation"]  # tanh of the mean
    assert (f"(λ_coll {ended[1]:.1f}, {late[1]:.3f} per episode; J_coll "
            f"{first[0]['summary']['J_coll']:.3f} sampled and "
            f"{first[1]['summary']['J_coll']:.3f} as tanh of its mean") in camera
    former = [json.loads((REPO / f"results/runs/pixels/obstacle_loop/CRLLK-D-curve1-a0.5-seed{s}/"
                          "test.json").read_text())["summary"]["J_coll"] for s in (0, 1, 2)]
    assert (f"the former default's runs (`CRLLK-D-curve1-a0.5-seed<S>`) gave J_coll "
            f"{former[0]:.3f}, {former[1]:.3f} and {former[2]:.3f} sampled") in camera
    replaced = REPO / "results/runs/pixels/replaced"
    first = [json.loads((replaced / "obstacle_loop/CRLLK-D-a0.5-seed2" / f"{n}.json")
                        .read_text()) for n in ("test", "test-mode")]
    retrained = REPO / "results/runs/pixels/obstacle_loop/CRLLK-D-curve1-a0.5-seed2"
    again = [json.loads((retrained / f"{n}.json").read_text())["summary"]["J_coll"]
             for n in ("test", "test-mode")]
    assert first[0]["evaluation"]["seed"] == first[1]["evaluation"]["seed"] == TEST_SEED
    assert "deployed" not in first[1]["evaluation"]  # the argmax
    assert (f"the first training gave J_coll {first[0]['summary']['J_coll']:.3f} sampled and "
            f"{first[1]['summary']['J_coll']:.3f} from its most probable action, the second "
            f"(`CRLLK-D-curve1-a0.5-seed2`) {again[0]:.3f} and {again[1]:.3f}") in camera
    for task, run in (("zigzag", "CRLLK-D-a0.5-seed2"), ("obstacle_loop",
                                                         "CRLLK-D-curve1-a0.5-seed2")):
        old_config = (replaced / task / "CRLLK-D-a0.5-seed2" / "config.yaml").read_text()
        new_config = (REPO / "results/runs/pixels" / task / run / "config.yaml").read_text()
        for line in ("seed: 2", "total_frames: 500000", "  margin: 0.07", "encounters: 0.5"):
            assert line in old_config and line in new_config
    teacher = json.loads((REPO / "results/scripted/teacher-obstacle_loop-margin0.07.json")
                         .read_text())["teacher"]
    assert teacher["summary"]["J_coll"] == 0
    assert teacher["breakdown"]["by_direction"]["intended"]["J_clane"] >= min(intended)


def _late_collisions(run: Path) -> float:
    """Mean training J_coll over a 500k-frame run's iterations 400–489 (its last), per row."""
    import csv

    with (run / "metrics.csv").open() as handle:
        late = [float(r["J_coll"]) for r in csv.DictReader(handle)
                if int(r["iteration"]) >= 400 and r["J_coll"] not in ("", "nan")]
    return sum(late) / len(late)


def _final_multiplier(run: Path) -> float:
    """λ_coll as a run's training ended."""
    import csv

    with (run / "metrics.csv").open() as handle:
        return float(list(csv.DictReader(handle))[-1]["lambda_collision"])


def _seeds_text(seeds: list[int]) -> str:
    """``seeds 0, 1 and 2``, ``seed 1``, or ``no seed``, as the results page says it."""
    if not seeds:
        return "no seed"
    if len(seeds) == 1:
        return f"seed {seeds[0]}"
    return "seeds " + ", ".join(map(str, seeds[:-1])) + f" and {seeds[-1]}"


def _misses(task: str, agents: dict[str, tuple[int, ...]], name: str) -> list[tuple]:
    """(agent, seed, J_coll) of the runs whose test evaluation misses a constraint."""
    found = []
    for agent, seeds in agents.items():
        for seed in seeds:
            summary = _test_document(task, agent, seed, name)["summary"]
            if summary["J_clane"] > 0.5 or summary["J_coll"] > 0.02:
                found.append((agent, seed, f"{summary['J_coll']:.2f}"))
    return found


def test_the_maps_without_obstacles_are_the_test_evaluations():
    """"every seed" on small_loop and zigzag, sampled and deployed (expected duties and
    expected actions), and the one sampled policy that holds only on its point estimate, as
    the prose names it; the fixed weights' one miss."""
    above = []
    for task in ("small_loop", "zigzag"):
        for name in ("test", "test-mode"):
            assert _misses(task, CRLLK_SEEDS, name) == []
            for agent, seeds in CRLLK_SEEDS.items():
                for seed in seeds:
                    document = _test_document(task, agent, seed, name)
                    if name == "test-mode":
                        assert document["evaluation"]["deployed"].startswith("expected_")
                    hits = sum(e["cost_collision"] > 0 for e in document["episodes"])
                    bound = wilson_interval(hits, len(document["episodes"]))[1]
                    if bound > 0.02:
                        above.append((task, agent, seed, name, document["summary"]["J_coll"],
                                      bound))
    assert len(above) == 1 and above[0][:4] == ("zigzag", "CRLLK-C", 0, "test")
    baselines = {"PPO-D": (0, 1), "PPO-C": (0, 1)}
    assert [m for task in ("small_loop", "zigzag") for m in _misses(task, baselines, "test")] \
        == [("PPO-C", 1, "0.03")]
    camera = prose("results/camera.md")
    assert (f"but one sampled policy (zigzag: CRLLK-C seed 0, J_coll {above[0][4]:.3f}, upper "
            f"bound {above[0][5]:.3f})") in camera
    assert ("on `small_loop` and `zigzag` on every seed, their sampled policies and their "
            "deployed ones") in prose("index.md")
    assert "one run (zigzag, PPO-C seed 1 sampled, J_coll 0.03)" in camera

COST_DISCOUNT_RUNS = (("default, seed 0", "CRLLK-D-curve1-a0.5-seed0"),
                      ("default, seed 1", "CRLLK-D-curve1-a0.5-seed1"),
                      ("`ppo.cost_gamma=0.99`, seed 0", "CRLLK-D-costgamma99-a0.5-seed0"),
                      ("`ppo.cost_gamma=0.99`, seed 1", "CRLLK-D-costgamma99-a0.5-seed1"))
"""The cost-discount trial's rows in the findings: label and run directory."""


def test_the_cost_discount_trial_rows_are_its_evaluations():
    """The cost-discount table of the findings: each run's validation evaluations, sampled
    and mode, all episodes and the blocked direction, and its final λ_coll."""
    root = REPO / "results/runs/pixels/obstacle_loop"

    def cell(document: dict) -> str:
        summary = document["summary"]
        blocked = document["breakdown"]["by_direction"]["intended"]
        return (f"{summary['J_clane']:.3f} / {summary['J_coll']:.2f}, blocked "
                f"{blocked['J_coll']:.3f}")

    for label, run in COST_DISCOUNT_RUNS:
        sampled, mode = (json.loads((root / run / f"{name}.json").read_text())
                         for name in ("eval", "eval-mode"))
        assert sampled["evaluation"]["seed"] == mode["evaluation"]["seed"] == 1_000_000
        lam = sampled["source"]["multipliers"]["collision"]
        assert f"| {label} | {cell(sampled)} | {cell(mode)} | {lam:.1f} |" in FINDINGS
    config = (root / "CRLLK-D-costgamma99-a0.5-seed0" / "config.yaml").read_text()
    assert "cost_gamma: 0.99" in config


def _val400_pair(run: Path) -> tuple[dict, dict]:
    """A run's ``val400`` and ``val400-mode`` evaluations, checked to be 400 validation
    episodes of the sampled policy and of its mode."""
    sampled, mode = (json.loads((run / f"{name}.json").read_text())
                     for name in ("val400", "val400-mode"))
    for document, deterministic in ((sampled, False), (mode, True)):
        assert document["evaluation"]["seed"] == 1_000_000
        assert document["evaluation"]["episodes"] == 400
        assert document["evaluation"]["deterministic"] is deterministic
    return sampled, mode


def test_the_cost_discount_rows_at_400_episodes_are_their_evaluations():
    """The 400-episode table of the cost-discount trial: each run's ``val400`` and
    ``val400-mode`` evaluations (validation seed, 400 episodes), all episodes and the blocked
    direction; and the prose's counts: sampled collisions in 800 episodes with and without the
    cost discount, seed 0's modes, seed 1's mode over α1, and how many hit the curve duckie."""
    root = REPO / "results/runs/pixels/obstacle_loop"

    def cell(document: dict) -> str:
        summary, episodes = document["summary"], document["episodes"]
        blocked = document["breakdown"]["by_direction"]["intended"]
        hits = int(sum(e["cost_collision"] for e in episodes))
        return (f"{summary['J_clane']:.3f} / {summary['J_coll']:.4f} ({hits} of "
                f"{len(episodes)}), blocked {blocked['J_clane']:.3f} / {blocked['J_coll']:.3f}")

    collisions, by_object = {}, {}
    for label, run in COST_DISCOUNT_RUNS:
        sampled, mode = _val400_pair(root / run)
        assert f"| {label} | {cell(sampled)} | {cell(mode)} |" in FINDINGS
        collisions[run] = [int(sum(e["cost_collision"] for e in d["episodes"]))
                           for d in (sampled, mode)]
        for document in (sampled, mode):
            for name, count in document["breakdown"]["collisions_by_object"].items():
                by_object[name] = by_object.get(name, 0) + count
    text = " ".join(FINDINGS.split())
    trial = [collisions[f"CRLLK-D-costgamma99-a0.5-seed{s}"] for s in (0, 1)]
    default = [collisions[f"CRLLK-D-curve1-a0.5-seed{s}"] for s in (0, 1)]
    assert f"({sum(t[0] for t in trial)} collisions in 800 episodes against " \
           f"{sum(d[0] for d in default)})" in text
    assert f"seed 0's mode collides {trial[0][1]} times where the default's collides once" \
        in text and default[0][1] == 1
    seed1 = json.loads((root / "CRLLK-D-costgamma99-a0.5-seed1" / "val400-mode.json").read_text())
    assert seed1["summary"]["J_clane"] > 0.5
    assert f"beyond α1 ({seed1['summary']['J_clane']:.3f} dm)" in text
    total = sum(by_object.values())
    assert f"Of the {total} episodes of the eight evaluations that ended on an obstacle, " \
           f"{by_object['3 duckie (0.88, 0.88)']} ended on the duckie in the centre" in text


CURVE_WEIGHT_RUNS = (("default, seed 0", "CRLLK-D-curve1-a0.5-seed0"),
                     ("default, seed 1", "CRLLK-D-curve1-a0.5-seed1"),
                     ("`encounter_curve_weight=4`, seed 0", "CRLLK-D-a0.5-seed0"),
                     ("`encounter_curve_weight=4`, seed 1", "CRLLK-D-a0.5-seed1"))
"""The curve-weight trial's rows in the findings: label and run directory."""


def _val400_cell(document: dict) -> str:
    """A findings cell of a 400-episode validation evaluation: all episodes, then each
    direction."""
    summary, episodes = document["summary"], document["episodes"]
    directions = document["breakdown"]["by_direction"]
    hits = int(sum(e["cost_collision"] for e in episodes))
    return (f"{summary['J_clane']:.3f} / {summary['J_coll']:.4f} ({hits} of {len(episodes)}), "
            f"blocked {directions['intended']['J_clane']:.3f} / "
            f"{directions['intended']['J_coll']:.3f}, reverse "
            f"{directions['reverse']['J_clane']:.3f}")


def test_the_curve_weight_rows_are_their_validation_evaluations():
    """The curve-weight table: each run's ``val400`` and ``val400-mode`` (validation seed, 400
    episodes); the prose's collision counts, modes over α1, reverse deviations and the
    trial runs' training lane cost and final λ_lane."""
    import csv

    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    collisions = {}
    for label, run in CURVE_WEIGHT_RUNS:
        sampled, mode = _val400_pair(root / run)
        assert f"| {label} | {_val400_cell(sampled)} | {_val400_cell(mode)} |" in FINDINGS
        collisions[run] = [int(sum(e["cost_collision"] for e in d["episodes"]))
                           for d in (sampled, mode)]
    trial = [v for run, v in collisions.items() if "curve1" not in run]
    default = [v for run, v in collisions.items() if "curve1" in run]
    assert (f"{sum(t[0] for t in trial)} of their 800 episodes ended on an obstacle or off the "
            f"road, against {sum(d[0] for d in default)}") in text
    assert (f"({sum(t[1] for t in trial)} such endings in 800 against "
            f"{sum(d[1] for d in default)})") in text
    modes = [json.loads((root / f"CRLLK-D-a0.5-seed{s}/val400-mode.json").read_text())
             for s in (0, 1)]
    assert all(m["summary"]["J_clane"] > 0.5 for m in modes)
    assert (f"beyond α1 ({modes[0]['summary']['J_clane']:.3f} and "
            f"{modes[1]['summary']['J_clane']:.3f} dm)") in text
    lane_costs, lambdas = [], []
    for seed in (0, 1):
        with (root / f"CRLLK-D-a0.5-seed{seed}/metrics.csv").open() as f:
            rows = list(csv.DictReader(f))
        late = [r for r in rows if int(r["iteration"]) >= 400 and r["J_clane"] != "nan"]
        episodes = sum(float(r["episodes"]) for r in late)
        lane_costs.append(sum(float(r["episodes"]) * float(r["J_clane"]) for r in late)
                          / episodes)
        lambdas.append(float(rows[-1]["lambda_lane"]))
        assert int(rows[-1]["iteration"]) - 400 + 1 == 90
    assert (f"training episodes {lane_costs[0]:.3f} and {lane_costs[1]:.3f} dm over the last 90 "
            f"iterations, λ_lane {lambdas[0]:.2f} at the end of both runs") in text
    assert lambdas[0] == lambdas[1]
    for seed in (0, 1):
        sampled = json.loads((root / f"CRLLK-D-a0.5-seed{seed}/val400.json").read_text())
        reverse = [d["breakdown"]["by_direction"]["reverse"]["J_clane"]
                   for d in (modes[seed], sampled)]
        assert 2 <= reverse[0] / reverse[1] <= 3  # "two to three times as much"
    ratios, pairs = [], []
    for seed in (0, 1):
        sampled, mode = _val400_pair(root / f"CRLLK-D-curve1-a0.5-seed{seed}")
        pair = [d["breakdown"]["by_direction"]["reverse"]["J_clane"] for d in (mode, sampled)]
        ratios.append(f"{pair[0] / pair[1]:.1f}")
        pairs.append(pair)
    assert (f"the default's modes deviate {ratios[0]} and {ratios[1]} times as much "
            f"({pairs[0][0]:.3f} and {pairs[1][0]:.3f} dm against {pairs[0][1]:.3f} and "
            f"{pairs[1][1]:.3f})") in text
    config = (root / "CRLLK-D-a0.5-seed0" / "config.yaml").read_text()
    assert "encounter_curve_weight: 4.0" in config


def test_the_curve_weight_s_shares_of_encounters_are_the_task_s():
    """"2 in 5" of the encounter episodes before an obstacle on a turning lane by default,
    "8 in 11" at W = 4, the curve duckie "4 in 11" instead of "1 in 5"."""
    from fractions import Fraction

    from crllk.tasks.config import load_task_config
    from crllk.tasks.lane_keeping import LaneKeeping, encounter_weights

    task = LaneKeeping(load_task_config(REPO / "tasks/obstacle_loop.yaml"), observation="state")
    turning = [bool(lane.turn) for lane, _ in task._blocking]
    assert len(turning) == 5 and sum(turning) == 2
    weights = encounter_weights(task._blocking, 4.0)
    on_turns = Fraction(float(sum(w for w, t in zip(weights, turning, strict=True) if t)))
    on_turns = on_turns.limit_denominator(20)
    assert on_turns == Fraction(8, 11)
    assert all(Fraction(float(w)).limit_denominator(20) == Fraction(4, 11)
               for w, t in zip(weights, turning, strict=True) if t)
    assert encounter_weights(task._blocking, 1.0) is None  # uniform: 1 in 5 each
    text = " ".join(FINDINGS.split())
    assert "got 2 in 5 of them" in text and "get 8 in 11 of the encounter episodes" in text
    assert "the curve duckie 4 in 11 instead of 1 in 5" in text


LANE_TARGET_RUNS = tuple((f"CRLLK-{agent}, seed {seed}",
                          f"CRLLK-{agent}-curve4-lane0.3-a0.5-seed{seed}")
                         for agent in "DC" for seed in (0, 1))
"""The lane-target trial's rows in the findings: label and run directory."""


def test_the_lane_target_rows_are_their_validation_evaluations():
    """The lane-target table (``val400`` and ``val400-mode`` of each run, final multipliers)
    and its prose: the multipliers' range, the collision counts against the curve weight
    alone, CRLLK-D's blocked-direction deviation, and the modes within α1."""
    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    sampled_hits, mode_hits, lane_lambdas, mode_lanes = [], [], [], []
    for label, run in LANE_TARGET_RUNS:
        sampled, mode = _val400_pair(root / run)
        multipliers = sampled["source"]["multipliers"]
        assert (f"| {label} | {_val400_cell(sampled)} | {_val400_cell(mode)} | "
                f"{multipliers['lane']:.2f} / {multipliers['collision']:.1f} |") in FINDINGS
        assert "target: 0.3" in (root / run / "config.yaml").read_text()
        sampled_hits.append(int(sum(e["cost_collision"] for e in sampled["episodes"])))
        mode_hits.append(int(sum(e["cost_collision"] for e in mode["episodes"])))
        lane_lambdas.append(multipliers["lane"])
        mode_lanes.append(mode["summary"]["J_clane"])
    alone = [_val400_pair(root / f"CRLLK-D-a0.5-seed{s}")[0] for s in (0, 1)]
    assert all(a["source"]["multipliers"]["lane"] == 0.0 for a in alone)
    assert f"λ_lane ends between {min(lane_lambdas):.2f} and {max(lane_lambdas):.2f}" in text
    alone_hits = [int(sum(e["cost_collision"] for e in a["episodes"])) for a in alone]
    assert (f"{sampled_hits[0]} and {sampled_hits[1]} of its 400 sampled episodes ended on an "
            f"obstacle or off the road, against {alone_hits[0]} and {alone_hits[1]} with the "
            f"curve weight alone (its modes: {mode_hits[0]} and {mode_hits[1]})") in text
    blocked = [_val400_pair(root / run)[0]["breakdown"]["by_direction"]["intended"]["J_clane"]
               for _, run in LANE_TARGET_RUNS[:2]]
    before = [a["breakdown"]["by_direction"]["intended"]["J_clane"] for a in alone]
    assert (f"it deviates {blocked[0]:.3f} and {blocked[1]:.3f} dm, against {before[0]:.3f} "
            f"and {before[1]:.3f} dm") in text
    import csv

    costs = []
    for _, run in LANE_TARGET_RUNS:
        with (root / run / "metrics.csv").open() as f:
            late = [r for r in csv.DictReader(f)
                    if int(r["iteration"]) >= 400 and r["J_clane"] != "nan"]
        episodes = sum(float(r["episodes"]) for r in late)
        costs.append(sum(float(r["episodes"]) * float(r["J_clane"]) for r in late) / episodes)
    assert f"reached the target ({costs[0]:.3f} and {costs[1]:.3f} dm" in text
    assert all(abs(c - 0.3) < 0.02 for c in costs[:2]) and all(c > 0.4 for c in costs[2:])
    assert f"did not reach the target ({costs[2]:.3f} and {costs[3]:.3f} dm" in text
    defaults = [json.loads((root / f"CRLLK-C-a0.5-seed{s}" / "eval-400.json").read_text())
                for s in (0, 1)]
    for document in defaults:
        assert document["evaluation"]["seed"] == 1_000_000
        assert document["evaluation"]["episodes"] == 400
        assert document["evaluation"]["deterministic"] is False
    default_hits = [int(sum(e["cost_collision"] for e in d["episodes"])) for d in defaults]
    assert (f"{sampled_hits[2]} and {sampled_hits[3]} of 400 sampled episodes, against "
            f"{default_hits[0]} and {default_hits[1]} for the default CRLLK-C") in text
    assert max(mode_lanes) <= 0.5
    assert f"hold α1 ({min(mode_lanes):.3f}–{max(mode_lanes):.3f} dm)" in text
    j_coll = [_val400_pair(root / run)[k]["summary"]["J_coll"]
              for _, run in LANE_TARGET_RUNS for k in (0, 1)]
    assert min(j_coll) > 0.02
    assert f"every run misses α2 (J_coll {min(j_coll):.4f}–{max(j_coll):.4f})" in text


CLOSER_TEACHER_RUNS = tuple((f"CRLLK-D, `teacher.margin=0.05`, seed {seed}",
                             f"CRLLK-D-curve4-margin5cm-a0.5-seed{seed}") for seed in (0, 1))
CURVE_WEIGHT_C_RUNS = tuple((f"CRLLK-C, seed {seed}", f"CRLLK-C-curve4-a0.5-seed{seed}")
                            for seed in (0, 1))
"""The rows of the closer-teacher and CRLLK-C curve-weight trials: label and run directory."""


def _endings(document: dict) -> int:
    """Episodes of an evaluation that ended on an obstacle or off the road."""
    return int(sum(e["cost_collision"] for e in document["episodes"]))


def test_the_closer_teacher_and_crllk_c_curve_weight_rows_are_their_evaluations():
    """The table of the two trials (``val400`` and ``val400-mode`` of each run, final
    multipliers, the settings in each run's config) and the prose's counts against the curve
    weight alone and against the default CRLLK-C on the same validation episodes."""
    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    counts = {}
    for label, run in CLOSER_TEACHER_RUNS + CURVE_WEIGHT_C_RUNS:
        sampled, mode = _val400_pair(root / run)
        multipliers = sampled["source"]["multipliers"]
        assert (f"| {label} | {_val400_cell(sampled)} | {_val400_cell(mode)} | "
                f"{multipliers['lane']:.2f} / {multipliers['collision']:.1f} |") in FINDINGS
        config = (root / run / "config.yaml").read_text()
        assert "encounter_curve_weight: 4.0" in config
        assert ("margin: 0.05" in config) == ("margin5cm" in run)
        counts[run] = (_endings(sampled), _endings(mode), mode["summary"]["J_clane"])
    closer = [counts[run] for _, run in CLOSER_TEACHER_RUNS]
    alone = [tuple(map(_endings, _val400_pair(root / f"CRLLK-D-a0.5-seed{s}")))
             for s in (0, 1)]
    alone_mode = json.loads((root / "CRLLK-D-a0.5-seed0/val400-mode.json").read_text())
    assert closer[0][2] > alone_mode["summary"]["J_clane"] > 0.5
    assert (f"Seed 0 ended {closer[0][0]} of its 400 sampled episodes on an obstacle or off the "
            f"road (against {alone[0][0]} with the 7 cm teacher) and its mode none, but that "
            f"mode deviates {closer[0][2]:.3f} dm, further beyond α1 than with the 7 cm "
            f"teacher ({alone_mode['summary']['J_clane']:.3f} dm)") in text and closer[0][1] == 0
    alone_mode1 = json.loads((root / "CRLLK-D-a0.5-seed1/val400-mode.json").read_text())
    assert closer[1][2] <= 0.5
    assert (f"seed 1's mode held α1 ({closer[1][2]:.3f} dm, against "
            f"{alone_mode1['summary']['J_clane']:.3f}), but seed 1 ended {closer[1][0]} of its "
            f"sampled episodes and {closer[1][1]} of its mode's that way, against "
            f"{alone[1][0]} and {alone[1][1]}") in text
    trial = [counts[run] for _, run in CURVE_WEIGHT_C_RUNS]
    default = [(json.loads((root / f"CRLLK-C-a0.5-seed{s}" / "eval-400.json").read_text()),
                json.loads((root / f"CRLLK-C-a0.5-seed{s}" / "val400-mode.json").read_text()))
               for s in (0, 1)]
    for sampled, mode in default:
        for document, deterministic in ((sampled, False), (mode, True)):
            assert document["evaluation"]["seed"] == 1_000_000
            assert document["evaluation"]["episodes"] == 400
            assert document["evaluation"]["deterministic"] is deterministic
    assert (f"{trial[0][0]} and {trial[1][0]} of its 400 sampled episodes ended on an obstacle "
            f"or off the road, against {_endings(default[0][0])} and {_endings(default[1][0])} "
            f"for the default CRLLK-C") in text
    assert (f"{trial[0][1]} and {trial[1][1]} of its mode's, against {_endings(default[0][1])} "
            f"and {_endings(default[1][1])}") in text
    curve_duckie = "3 duckie (0.88, 0.88)"
    hits = [d[0]["breakdown"]["collisions_by_object"] for d in default]
    assert (f"hit it in {hits[0][curve_duckie]} of {_endings(default[0][0])} and "
            f"{hits[1][curve_duckie]} of {_endings(default[1][0])} such episodes") in text
    others = {name for h in hits for name in h if name != curve_duckie}
    rest = [sum(h.values()) - h[curve_duckie] for h in hits]
    off_road = [d[0]["terminations"].get("off_road", 0) for d in default]
    assert [sum(h.values()) + o for h, o in zip(hits, off_road, strict=True)] == \
        [_endings(d[0]) for d in default]  # collisions and off-road endings make up the count
    assert (f"the other {rest[0]} and {rest[1]} collisions were with "
            f"{['no', 'one', 'two', 'three', 'four', 'five'][len(others)]} other obstacles "
            f"between them, and {off_road[0]} and {off_road[1]} episodes left the road") in text
    weighted = [json.loads((root / run / "val400.json").read_text())["breakdown"]
                ["collisions_by_object"][curve_duckie] for _, run in CURVE_WEIGHT_C_RUNS]
    assert (f"seed 0's sampled policy hit it {weighted[0]} times with the weight, against "
            f"{hits[0][curve_duckie]} without (seed 1: {weighted[1]} against "
            f"{hits[1][curve_duckie]})") in text


DEPLOYED_RUNS = (("default, seed 0", "CRLLK-D-curve1-a0.5-seed0"),
                 ("default, seed 1", "CRLLK-D-curve1-a0.5-seed1"),
                 *((f"`encounter_curve_weight=4`, seed {s}", f"CRLLK-D-a0.5-seed{s}")
                   for s in (0, 1, 2)))
"""The rows of the deployed-policy trial: label and run directory."""


def test_the_deployed_policy_rows_are_their_validation_evaluations():
    """The expected-duty trial: each run's ``val400`` (sampled), ``val400-mode`` (the most
    probable action) and ``val400-deployed`` (the expected duties, recorded so), all 400
    validation episodes; the prose's counts and ranges."""
    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    rows = []
    for label, run in DEPLOYED_RUNS:
        sampled, mode = _val400_pair(root / run)
        deployed = json.loads((root / run / "val400-deployed.json").read_text())
        assert deployed["evaluation"] == {"episodes": 400, "seed": 1_000_000, "num_envs": 10,
                                          "deterministic": True, "deployed": "expected_duty"}
        assert "deployed" not in mode["evaluation"]  # the argmax, evaluated before
        assert (f"| {label} | {_val400_cell(sampled)} | {_val400_cell(mode)} | "
                f"{_val400_cell(deployed)} |") in FINDINGS
        rows.append((sampled, mode, deployed))
    endings = [sum(_endings(r[k]) for r in rows) for k in range(3)]
    assert (f"ended none of their 2,000 episodes on an obstacle or off the road, against "
            f"{endings[0]} for the sampled policies and {endings[1]} for the most probable "
            "actions") in text and endings[2] == 0

    def span(values: list[float], digits: int) -> str:
        return f"{min(values):.{digits}f}–{max(values):.{digits}f}"

    reverse = [[r[k]["breakdown"]["by_direction"]["reverse"]["J_clane"] for r in rows]
               for k in range(3)]
    blocked = [r[2]["breakdown"]["by_direction"]["intended"]["J_clane"] for r in rows]
    lane = [r[2]["summary"]["J_clane"] for r in rows]
    travel = [[r[k]["summary"]["J_R"] for r in rows] for k in (0, 2)]
    assert (f"J_clane {span(lane, 3)} dm over all episodes, {span(reverse[2], 3)} dm in the "
            f"reverse direction, where the most probable action deviated "
            f"{span(reverse[1], 3)} dm") in text
    assert f"(J_R {span(travel[1], 2)} m, against {span(travel[0], 2)} m sampled)" in text
    assert f"the expected duties still deviate {span(blocked, 3)} dm, over α1" in text
    assert min(travel[1]) > min(travel[0]) and max(lane) <= 0.5
    for sampled, mode, deployed in rows:
        for key in ("J_clane",):
            assert deployed["summary"][key] < min(sampled["summary"][key], mode["summary"][key])
        directions = [r["breakdown"]["by_direction"] for r in (sampled, mode, deployed)]
        assert directions[2]["reverse"]["J_clane"] < min(d["reverse"]["J_clane"]
                                                          for d in directions[:2])
    least_blocked = sum(r[2]["breakdown"]["by_direction"]["intended"]["J_clane"]
                        < min(r[k]["breakdown"]["by_direction"]["intended"]["J_clane"]
                              for k in (0, 1)) for r in rows)
    assert least_blocked == 4 and "(in the blocked direction on four of five)" in text
    weighted, former = (sum(_endings(r[0]) for r in part) for part in (rows[2:], rows[:2]))
    assert (f"their sampled policies ended {weighted} of 1,200 validation episodes on an "
            f"obstacle or off the road, against {former} of 800 for the former default") in text


NOENTROPY_RUNS = (("default, seed 0", "CRLLK-C-a0.5-seed0"),
                  ("default, seed 1", "CRLLK-C-a0.5-seed1"),
                  ("`ppo.entropy_coeff=0`, seed 0", "CRLLK-C-noentropy-a0.5-seed0"),
                  ("`ppo.entropy_coeff=0`, seed 1", "CRLLK-C-noentropy-a0.5-seed1"))


def _steering_scale(run: Path) -> float:
    """σ of a Gaussian policy's steering before the tanh, as its run ended."""
    import torch

    actor = torch.load(run / "policy.pt", weights_only=True, map_location="cpu")["actor"]
    log_std = next(v for k, v in actor.items() if k.endswith("log_std"))[1].item()
    bound = _max_log_std(run)
    return math.exp(log_std if bound is None else min(log_std, bound))


def _max_log_std(run: Path) -> float | None:
    """The run's ``model.max_log_std`` (None: unbounded, also for runs from before it)."""
    return _model_setting(run, "max_log_std")


def _model_setting(run: Path, name: str) -> Any:
    """The run's ``model.<name>`` (None for runs from before the setting)."""
    from crllk.yaml_files import read_yaml

    return (read_yaml(run / "config.yaml").get("model") or {}).get(name)


def test_the_crllk_c_noise_and_no_bonus_rows_are_the_runs():
    """The CRLLK-C section: the endings of the default runs' sampled validation episodes by
    obstacle, the steering noise of every Gaussian run from pixels, and the no-bonus rows."""
    import csv

    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    endings = [e for s in (0, 1) for e in json.loads(
        (root / f"CRLLK-C-a0.5-seed{s}/eval-400.json").read_text())["episodes"]
        if e["cost_collision"] > 0]
    curve = sum(e["hit_object"] == 3 for e in endings)
    cone = sum(e["hit_object"] == 2 and e["direction"] == "reverse" for e in endings)
    assert (f"end {len(endings)} times on an obstacle or off the road: {curve} times on the "
            f"curve duckie, {cone} times on the cone of the right column in the reverse "
            f"direction, whose lane it does not block, and {len(endings) - curve - cone} times "
            "elsewhere") in text
    scales = [_steering_scale(p.parent) for p in (REPO / "results/runs/pixels").glob(
        "*/*-C-*/policy.pt")  # finished runs (a run still training has no eval.json yet)
        if _max_log_std(p.parent) is None and (p.parent / "eval.json").exists()
        and not _model_setting(p.parent, "state_dependent_std")]
    assert len(scales) >= 20
    assert f"from 0.61 at the start to {min(scales):.2f}–{max(scales):.2f} in every kept" in text
    starts = {float(line.split(":")[1]) for p in (REPO / "results/runs/pixels").glob(
        "*/*-C-*/config.yaml") for line in p.read_text().splitlines()
        if line.strip().startswith("initial_log_std:")}
    assert len(starts) == 1 and f"{math.exp(starts.pop()):.2f}" == "0.61"
    for label, run in NOENTROPY_RUNS:
        with (root / run / "metrics.csv").open() as handle:
            late = [float(r["J_coll"]) for r in csv.DictReader(handle)
                    if 400 <= int(r["iteration"]) <= 489 and r["J_coll"] not in ("", "nan")]
        final = json.loads((root / run / "eval.json").read_text())
        assert final["evaluation"]["episodes"] == 100
        summary = final["summary"]
        assert (f"| {label} | {_steering_scale(root / run):.2f} | {sum(late) / len(late):.3f} | "
                f"{summary['J_clane']:.3f} / {summary['J_coll']:.2f} / {summary['J_R']:.2f} |"
                ) in FINDINGS
    for _, run in NOENTROPY_RUNS[2:]:
        assert "  entropy_coeff: 0.0\n" in (root / run / "config.yaml").read_text()


def test_the_expected_action_rows_are_their_validation_evaluations():
    """The expected-action trial: sampled (``eval-400``), tanh of the mean (``val400-mode``,
    recorded before the deployed form was) and the expected action (``val400-deployed``), all
    400 validation episodes; the prose's counts."""
    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    rows = []
    for seed in (0, 1):
        run = root / f"CRLLK-C-a0.5-seed{seed}"
        sampled, mode, deployed = (json.loads((run / f"{n}.json").read_text())
                                   for n in ("eval-400", "val400-mode", "val400-deployed"))
        assert deployed["evaluation"] == {"episodes": 400, "seed": 1_000_000, "num_envs": 10,
                                          "deterministic": True,
                                          "deployed": "expected_action"}
        assert "deployed" not in mode["evaluation"] and mode["evaluation"]["deterministic"]
        assert sampled["evaluation"]["deterministic"] is False
        assert (f"| seed {seed} | {_val400_cell(sampled)} | {_val400_cell(mode)} | "
                f"{_val400_cell(deployed)} |") in FINDINGS
        rows.append((sampled, mode, deployed))
    ends = [sum(_endings(r[k]) for r in rows) for k in range(3)]
    assert (f"ended {ends[2]} of their 800 episodes on an obstacle or off the road, against "
            f"{ends[0]} for the sampled policies and {ends[1]} for tanh of the mean") in text
    lanes = " and ".join(f"{r[2]['summary']['J_clane']:.3f}" for r in rows)
    assert f"(J_clane {lanes} dm)" in text
    for sampled, mode, deployed in rows:
        assert deployed["summary"]["J_clane"] < min(sampled["summary"]["J_clane"],
                                                    mode["summary"]["J_clane"])
        reverse = [d["breakdown"]["by_direction"]["reverse"]["J_clane"]
                   for d in (sampled, mode, deployed)]
        assert reverse[2] < min(reverse[:2])


NOISE_BOUND_RUNS = (("default, seed 0", "CRLLK-C-a0.5-seed0", "eval-400"),
                    ("default, seed 1", "CRLLK-C-a0.5-seed1", "eval-400"),
                    ("`model.max_log_std=-0.5`, seed 0", "CRLLK-C-maxstd-a0.5-seed0", "val400"),
                    ("`model.max_log_std=-0.5`, seed 1", "CRLLK-C-maxstd-a0.5-seed1", "val400"))
"""The noise-bound trial's rows: label, run directory and its sampled 400-episode evaluation."""


def test_the_noise_bound_rows_are_their_validation_evaluations():
    """The noise-bound trial: sampled and expected-action evaluations (validation seed, 400
    episodes), the training collisions of iterations 400–489 and the final λ_coll; the prose's
    counts and the bound in the runs' configurations."""
    import csv

    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    ends, curve = {}, 0
    for label, run, sampled_name in NOISE_BOUND_RUNS:
        sampled, deployed = (json.loads((root / run / f"{n}.json").read_text())
                             for n in (sampled_name, "val400-deployed"))
        for document in (sampled, deployed):
            assert document["evaluation"]["seed"] == 1_000_000
            assert document["evaluation"]["episodes"] == 400
        assert deployed["evaluation"]["deployed"] == "expected_action"
        assert sampled["evaluation"]["deterministic"] is False
        with (root / run / "metrics.csv").open() as handle:
            rows = list(csv.DictReader(handle))
        late = [float(r["J_coll"]) for r in rows
                if 400 <= int(r["iteration"]) <= 489 and r["J_coll"] not in ("", "nan")]
        multiplier = float(rows[-1]["lambda_collision"])
        assert (f"| {label} | {_val400_cell(sampled)} | {_val400_cell(deployed)} | "
                f"{sum(late) / len(late):.3f} | {multiplier:.1f} |") in FINDINGS
        bounded = "maxstd" in run
        ends.setdefault(bounded, []).append((_endings(sampled), _endings(deployed)))
        if bounded:
            assert "max_log_std: -0.5" in (root / run / "config.yaml").read_text()
            curve += deployed["breakdown"]["collisions_by_object"].get(
                "3 duckie (0.88, 0.88)", 0)
    bounded, default = ([sum(e[k] for e in ends[b]) for k in (0, 1)] for b in (True, False))
    assert (f"{bounded[0]} of its 800 sampled validation episodes ended on an obstacle or off "
            f"the road, against {default[0]} for the default, and its expected action "
            f"{bounded[1]}, against {default[1]}") in text
    assert f"hit the curve duckie {curve} times" in text


def test_the_real_map_page_quotes_the_retrained_and_the_replaced_runs():
    """The real-maps page's prose: regress_4way_adam's test J_coll of the runs trained again
    and of the replaced ones, sampled and deployed, from their test evaluations."""
    runs = REPO / "results/runs/pixels"

    def j_coll(where: str, seed: int, name: str) -> str:
        path = runs / where / f"CRLLK-D-a0.5-seed{seed}" / f"{name}.json"
        return f"{json.loads(path.read_text())['summary']['J_coll']:.3f}"

    def pair(where: str, name: str) -> str:
        return f"{j_coll(where, 0, name)} and {j_coll(where, 1, name)}"

    text = prose("results/realmaps.md")
    former = json.loads((runs / "replaced/ETH_small_intersect/CRLLK-D-a0.5-seed0/test-mode.json"
                         ).read_text())
    assert (f"(the former deployed policy of seed 0 missed α2: J_coll "
            f"{former['summary']['J_coll']:.3f}, {former['terminations']['off_road']} episodes "
            "off the road)") in text
    new, old = "regress_4way_adam", "replaced/regress_4way_adam"
    assert f"sampled (J_coll {pair(new, 'test')}, against {pair(old, 'test')} before)" in text
    assert (f"deployed ({pair(new, 'test-mode')}, against {pair(old, 'test-mode')} for the "
            "former deployed policy") in text


def test_the_twice_the_budget_rows_are_their_validation_evaluations():
    """The CRLLK-C budget trial: each run's sampled and expected-action validation episodes,
    its late training J_coll and final λ_coll; the prose's counts."""
    import csv

    root = REPO / "results/runs/pixels/obstacle_loop"

    def late(run: str, low: int, high: int) -> tuple[float, float]:
        with (root / run / "metrics.csv").open() as handle:
            rows = list(csv.DictReader(handle))
        values = [float(r["J_coll"]) for r in rows
                  if low <= int(r["iteration"]) <= high and r["J_coll"] not in ("", "nan")]
        return sum(values) / len(values), float(rows[-1]["lambda_collision"])

    hits = {}
    for label, run, sampled, low, high, frames in [
            ("default (500,000 frames), seed 0", "CRLLK-C-a0.5-seed0", "eval-400", 400, 489,
             500_000),
            ("default (500,000 frames), seed 1", "CRLLK-C-a0.5-seed1", "eval-400", 400, 489,
             500_000),
            ("default (500,000 frames), seed 2", "CRLLK-C-a0.5-seed2", "val400", 400, 489,
             500_000),
            ("1,000,000 frames, seed 0", "CRLLK-C-1M-a0.5-seed0", "val400", 888, 977, 1_000_000),
            ("1,000,000 frames, seed 1", "CRLLK-C-1M-a0.5-seed1", "val400", 888, 977, 1_000_000),
            ("1,000,000 frames, seed 2", "CRLLK-C-1M-a0.5-seed2", "val400", 888, 977,
             1_000_000)]:
        assert f"total_frames: {frames}" in (root / run / "config.yaml").read_text()
        documents = [json.loads((root / run / f"{name}.json").read_text())
                     for name in (sampled, "val400-deployed")]
        assert documents[1]["evaluation"]["deployed"] == "expected_action"
        assert all(d["evaluation"]["seed"] != TEST_SEED for d in documents)
        j_coll, multiplier = late(run, low, high)
        assert (f"| {label} | {_val400_cell(documents[0])} | {_val400_cell(documents[1])} | "
                f"{j_coll:.3f} | {multiplier:.1f} |") in FINDINGS
        hits[run] = [int(sum(e["cost_collision"] for e in d["episodes"])) for d in documents]
    text = " ".join(FINDINGS.split())
    old, new = hits["CRLLK-C-a0.5-seed2"], hits["CRLLK-C-1M-a0.5-seed2"]
    assert (f"its sampled policy ended {new[0]} of 400 validation episodes on an obstacle or off "
            f"the road, against {old[0]} at 500,000 frames, and its expected action {new[1]}, "
            f"against {old[1]}") in text
    deployed = json.loads((root / "CRLLK-C-1M-a0.5-seed2/val400-deployed.json").read_text())
    upper = wilson_interval(new[1], 400)[1]
    assert (f"(J_coll {deployed['summary']['J_coll']:.4f}: within α2 on the point estimate, not "
            f"at the 95 % upper bound, {upper:.3f})") in text
    clane = [json.loads((root / run / "val400.json").read_text())["summary"]["J_clane"]
             for run in ("CRLLK-C-1M-a0.5-seed2", "CRLLK-C-a0.5-seed2")]
    assert f"at a higher J_clane ({clane[0]:.3f} dm against {clane[1]:.3f})" in text
    old, new = hits["CRLLK-C-a0.5-seed0"], hits["CRLLK-C-1M-a0.5-seed0"]
    assert (f"({new[0]} sampled endings against {old[0]}, its expected action {new[1]} against "
            f"{old[1]})") in text
    lates = [late(run, low, high)[0] for run, low, high in
             (("CRLLK-C-1M-a0.5-seed0", 888, 977), ("CRLLK-C-a0.5-seed0", 400, 489))]
    assert f"collided more late on ({lates[0]:.3f} per episode against {lates[1]:.3f})" in text
    old, new = hits["CRLLK-C-a0.5-seed1"], hits["CRLLK-C-1M-a0.5-seed1"]
    assert (f"got worse: {new[0]} sampled endings against {old[0]}, and its expected action "
            f"{new[1]} against {old[1]}") in text

    def sampled(run: str) -> str:
        name = "eval-400" if run in ("CRLLK-C-a0.5-seed0", "CRLLK-C-a0.5-seed1") else "val400"
        value = json.loads((root / run / f"{name}.json").read_text())["summary"]["J_coll"]
        assert value > 0.02
        return f"{value:.3f}"

    longer = ", ".join(sampled(f"CRLLK-C-1M-a0.5-seed{s}") for s in (0, 1)) + " and " + \
        sampled("CRLLK-C-1M-a0.5-seed2")
    shorter = ", ".join(sampled(f"CRLLK-C-a0.5-seed{s}") for s in (0, 1)) + " and " + \
        sampled("CRLLK-C-a0.5-seed2")
    assert (f"misses α2 on every seed at either budget (J_coll {longer} at 1,000,000 frames; "
            f"{shorter} at 500,000)") in text

    def windows(run: str, first: int, count: int) -> str:
        values = [f"{late(run, low, low + 99)[0]:.3f}"
                  for low in range(first, first + 100 * count, 100)]
        return ", ".join(values[:-1]) + " and " + values[-1]

    assert (f"Seed 1's mean training J_coll per 100 iterations fell to "
            f"{windows('CRLLK-C-1M-a0.5-seed1', 401, 2)} over iterations 401–600, then rose "
            f"again to {windows('CRLLK-C-1M-a0.5-seed1', 601, 4)}") in text
    assert (f"seed 0's went {windows('CRLLK-C-1M-a0.5-seed0', 301, 7)} over iterations "
            "301–977") in text
    assert f"Seed 2's fell to {late('CRLLK-C-1M-a0.5-seed2', 901, 977)[0]:.3f} only" in text
    with (root / "CRLLK-C-1M-a0.5-seed1" / "metrics.csv").open() as handle:
        multipliers = {int(r["iteration"]): float(r["lambda_collision"])
                       for r in csv.DictReader(handle)}
    assert (f"its λ_coll hardly moved ({multipliers[401]:.1f} at iteration 401, "
            f"{multipliers[601]:.1f} at 601, {multipliers[901]:.1f} at 901)") in text


COLLISION_CRITIC_RUNS = (("default (500,000 frames), seed 2", "CRLLK-C-a0.5-seed2"),
                         ("1,000,000 frames, seed 1", "CRLLK-C-1M-a0.5-seed1"))


def test_the_collision_critic_lead_table_is_the_runs_calibration():
    """Each row: the run's ``cost-critic-collision.json`` (60 batches, the training cost
    discount); the prose's totals and loss ratios are those files' and ``metrics.csv``'s."""
    import csv

    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    collisions = frames = above = 0
    ratios = []
    for label, run in COLLISION_CRITIC_RUNS:
        fit = json.loads((root / run / "cost-critic-collision.json").read_text())
        assert fit["frames"] == 61_440 and fit["cost_gamma"] == 0.95
        cells = " | ".join(f"{w['predicted']:.3f} → {w['realised']:.3f}" for w in fit["lead"])
        assert f"| {label} | {fit['cost_steps']} | {cells} |" in FINDINGS.splitlines()
        collisions, frames = collisions + fit["cost_steps"], frames + fit["frames"]
        above += sum(b["steps"] for b in fit["calibration"] if b["from"] is not None
                     and b["from"] >= 0.1)
        with (root / run / "metrics.csv").open() as handle:
            rows = list(csv.DictReader(handle))
        rows = rows[len(rows) // 2:]  # the second half of the run
        ratios.append(sum(float(r["loss_cost_critic"]) for r in rows)
                      / sum(float(r["loss_critic"]) for r in rows))
    assert f"(one step of {frames:,} above)" in text and above == 1
    assert f"{ratios[0]:.0f} and {ratios[1]:.0f} times the reward critic's" in text
    assert f"({collisions} of the {frames:,} collected steps carry a collision)" in text


AGAIN_TEACHER_RUNS = (("floor 0.3 (default)", "", ("val400", "val400-deployed")),
                      ("no teacher", "-noteacher", ("val400", "val400-deployed")),
                      ("annealed to 0 by 400k frames", "-teacher0", ("eval", "eval-deployed")))


@pytest.mark.parametrize(("label", "tag", "names"), AGAIN_TEACHER_RUNS)
def test_the_teacher_again_table_is_the_validation_evaluations(label, tag, names):
    """The teacher chosen again under the curve weight: each row is the runs' validation
    evaluations (sampled, then the expected duties), never the test seed."""
    from crllk.protocol import VALIDATION_SEED

    root = REPO / "results/runs/pixels/obstacle_loop"
    for seed in (0, 1):
        docs = [json.loads((root / f"CRLLK-D{tag}-a0.5-seed{seed}" / f"{n}.json").read_text())
                for n in names]
        assert [d["evaluation"]["seed"] for d in docs] == [VALIDATION_SEED] * 2
        assert [d["evaluation"]["deterministic"] for d in docs] == [False, True]
        assert docs[1]["evaluation"]["deployed"] == "expected_duty"
        cells = []
        for d in docs:
            hits = int(sum(e["cost_collision"] for e in d["episodes"]))
            blocked = d["breakdown"]["by_direction"]["intended"]
            cells.append(f"{d['summary']['J_clane']:.3f} / {d['summary']['J_coll']:.4f} "
                         f"({hits} of {len(d['episodes'])}), blocked "
                         f"{blocked['J_clane']:.3f} / {blocked['J_coll']:.3f}")
        assert f"| {label}, seed {seed} | {cells[0]} | {cells[1]} |" in FINDINGS.splitlines()


def test_the_annealed_teacher_s_collapse_is_its_training():
    import csv

    text = " ".join(FINDINGS.split())
    late, final = [], []
    for seed in (0, 1):
        path = REPO / f"results/runs/pixels/obstacle_loop/CRLLK-D-teacher0-a0.5-seed{seed}"
        with (path / "metrics.csv").open() as handle:
            rows = list(csv.DictReader(handle))
        window = [r for r in rows if 401 <= int(r["iteration"]) <= 489]
        episodes = sum(float(r["episodes"]) for r in window)
        late.append(sum(float(r["J_coll"]) * float(r["episodes"]) for r in window
                        if float(r["episodes"]) > 0) / episodes)
        final.append(float(rows[-1]["lambda_collision"]))
    assert (f"{late[0]:.2f} and {late[1]:.2f} over 401–489) and λ_coll climbs from about 18 to "
            f"{final[0]:.1f} and {final[1]:.1f}") in text


def test_the_teacherless_runs_pass_the_blocked_direction_as_quoted():
    root = REPO / "results/runs/pixels/obstacle_loop"
    passed = sorted(round(100 * (1 - json.loads(
        (root / f"CRLLK-D-noteacher-a0.5-seed{s}" / "val400.json").read_text())
        ["breakdown"]["by_direction"]["intended"]["J_coll"])) for s in (0, 1))
    assert f"it still passes {passed[0]}–{passed[1]} % of the approaches" in " ".join(
        FINDINGS.split())


def _crllk_c_trial_row(root: Path, label: str, run: str, sampled_name: str
                       ) -> tuple[dict, dict, list[dict], list[float]]:
    """A CRLLK-C trial's findings row: its sampled and expected-action validation evaluations
    (400 episodes), then the mean training J_coll over iterations 400–489 and the final
    λ_coll, asserted in the page; returns the two evaluations, the late rows of
    ``metrics.csv`` and their J_coll values."""
    import csv

    sampled, deployed = (json.loads((root / run / f"{n}.json").read_text())
                         for n in (sampled_name, "val400-deployed"))
    assert all(d["evaluation"]["seed"] == 1_000_000 and d["evaluation"]["episodes"] == 400
               for d in (sampled, deployed))
    assert deployed["evaluation"]["deployed"] == "expected_action"
    assert sampled["evaluation"]["deterministic"] is False
    assert f"\nseed: {label.rsplit(' ', 1)[1]}\n" in (root / run / "config.yaml").read_text()
    with (root / run / "metrics.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    late = [r for r in rows if 400 <= int(r["iteration"]) <= 489]
    j_coll = [float(r["J_coll"]) for r in late if r["J_coll"] not in ("", "nan")]
    assert (f"| {label} | {_val400_cell(sampled)} | {_val400_cell(deployed)} | "
            f"{sum(j_coll) / len(j_coll):.3f} | {float(rows[-1]['lambda_collision']):.1f} |"
            ) in FINDINGS
    return sampled, deployed, late, j_coll


def _collision_critic_row(root: Path, label: str, run: str, cost_gamma: float) -> dict:
    """A 500,000-frame run's ``cost-critic-collision.json`` (60 batches, the run's cost
    discount), its lead row asserted in the page; returns the file's content."""
    fit = json.loads((root / run / "cost-critic-collision.json").read_text())
    assert fit["frames"] == 61_440 and fit["cost_gamma"] == cost_gamma
    assert "total_frames: 500000" in (root / run / "config.yaml").read_text()
    cells = " | ".join(f"{w['predicted']:.3f} → {w['realised']:.3f}" for w in fit["lead"])
    assert f"| {label} | {fit['cost_steps']} | {cells} |" in FINDINGS.splitlines()
    return fit


def _crllk_c_trial_runs(label: str, tag: str) -> tuple[tuple[str, str, str], ...]:
    """A CRLLK-C trial's rows against the default's (seeds 0 and 1): label, run directory and
    its sampled 400-episode evaluation."""
    return (*((f"default, seed {s}", f"CRLLK-C-a0.5-seed{s}", "eval-400") for s in (0, 1)),
            *((f"{label}, seed {s}", f"CRLLK-C-{tag}-a0.5-seed{s}", "val400") for s in (0, 1)))


SEPARATE_CRITIC_RUNS = _crllk_c_trial_runs("separate critics", "separatecritics")
"""The separate-critics trial's rows."""


def test_the_separate_critics_rows_are_their_evaluations_and_critics():
    """The separate-critics trial: sampled and expected-action validation evaluations, late
    training J_coll and final λ_coll; the collision critics' lead rows and calibration, and
    the prose's counts, against the shared critics' files."""

    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    ends = {}
    for label, run, sampled_name in SEPARATE_CRITIC_RUNS:
        sampled, deployed, _, _ = _crllk_c_trial_row(root, label, run, sampled_name)
        separate = "separatecritics" in run
        assert (f"shared_critic: {str(not separate).lower()}"
                in (root / run / "config.yaml").read_text())
        ends.setdefault(separate, []).append((_endings(sampled), _endings(deployed)))
    trial, default = ends[True], ends[False]
    assert (f"ended {trial[0][0]} and {trial[1][0]} of their 400 validation episodes on an "
            f"obstacle or off the road, against {default[0][0]} and {default[1][0]} for the "
            f"default, and the expected actions {trial[0][1]} and {trial[1][1]}, against "
            f"{default[0][1]} and {default[1][1]}") in text
    top, shared_top, variances, shared_variances, collisions = [], [], [], [], []
    correlations, shared_correlations = [], []
    for label, run, _ in SEPARATE_CRITIC_RUNS[2:]:
        fit = _collision_critic_row(root, label, run, 0.95)
        assert f"{fit['lead'][0]['predicted']:.2f}" == "0.03"
        assert f"{fit['lead'][0]['realised']:.2f}" == "0.80"
        bins = [b for b in fit["calibration"] if b["to"] is not None and b["to"] <= 0.1]
        realised = [b["realised"] for b in bins]
        assert len(bins) == 5 and realised == sorted(realised)  # rises with the prediction
        top.append(bins[-1])
        correlations.append(fit["realised_correlation"])
        variances.append(fit["explained_variance"])
        collisions.append(fit["cost_steps"])
    assert collisions[0] == 3 and "seed 0's row averages only 3 approaches" in text
    for _, run in COLLISION_CRITIC_RUNS:
        fit = json.loads((root / run / "cost-critic-collision.json").read_text())
        bins = [b for b in fit["calibration"] if b["to"] is not None and b["to"] <= 0.1]
        realised = [b["realised"] for b in bins]
        assert realised != sorted(realised)
        shared_top.append(bins[-1])
        shared_correlations.append(fit["realised_correlation"])
        shared_variances.append(fit["explained_variance"])
    assert all(b["from"] == 0.03 and b["to"] == 0.1 for b in top + shared_top)
    assert (f"the prediction {top[0]['predicted']:.3f} is followed by {top[0]['realised']:.3f} "
            f"and {top[1]['predicted']:.3f} by {top[1]['realised']:.3f} ({top[0]['steps']:,} "
            f"and {top[1]['steps']:,} steps), where the shared critics' "
            f"{shared_top[0]['predicted']:.3f} and {shared_top[1]['predicted']:.3f} were "
            f"followed by {shared_top[0]['realised']:.3f} and {shared_top[1]['realised']:.3f} "
            f"({shared_top[0]['steps']:,} and {shared_top[1]['steps']:,} steps)") in text
    assert (f"is positive, {variances[0]:.3f} and {variances[1]:.3f}, against "
            f"{shared_variances[0]:.3f} and {shared_variances[1]:.3f}."
            ).replace("-", "−") in text
    assert min(variances) > 0 > max(shared_variances)
    figures = [f"{c:.3f}".replace("-", "−") for c in correlations + shared_correlations]
    assert (f"correlate with the realised cost-to-go ({figures[0]} and {figures[1]}, against "
            f"{figures[2]} and {figures[3]})") in text
    assert f"with {collisions[0]} and {collisions[1]} collisions in 61,440 steps" in text


COST_DISCOUNT_C_RUNS = _crllk_c_trial_runs("`ppo.cost_gamma=0.99`", "costgamma99")
"""CRLLK-C's cost-discount trial's rows."""


def test_crllk_c_s_cost_discount_rows_are_their_evaluations():
    """CRLLK-C with ``ppo.cost_gamma=0.99``: the rows (validation evaluations, late training
    J_coll, final λ_coll), the late explained variance of the collision critic and the
    prose's counts."""

    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    hits, lates, variances = {}, {}, {}
    for label, run, sampled_name in COST_DISCOUNT_C_RUNS:
        sampled, deployed, late, j_coll = _crllk_c_trial_row(root, label, run, sampled_name)
        explained = [float(r["explained_variance_collision"]) for r in late]
        trial = "costgamma99" in run
        assert ("cost_gamma: 0.99" in (root / run / "config.yaml").read_text()) == trial
        hits.setdefault(trial, []).append((_endings(sampled), _endings(deployed)))
        lates.setdefault(trial, []).append(f"{sum(j_coll) / len(j_coll):.3f}")
        variances.setdefault(trial, []).append(
            f"{sum(explained) / len(explained):.3f}".replace("-", "−"))
    assert (f"mean over iterations 400–489) is positive, {variances[True][0]} and "
            f"{variances[True][1]}, where the default's is negative ({variances[False][0]} and "
            f"{variances[False][1]})") in text
    assert (f"{hits[True][0][0]} and {hits[True][1][0]} of their 400 validation episodes ended "
            f"on an obstacle or off the road, against {hits[False][0][0]} and "
            f"{hits[False][1][0]}, and their training episodes {lates[True][0]} and "
            f"{lates[True][1]} per episode late in training, against {lates[False][0]} and "
            f"{lates[False][1]}") in text
    assert hits[True][1][1] / 400 > 0.02
    assert f"Seed 1's expected action missed α2 ({hits[True][1][1]} of 400)" in text
    assert hits[True][0][1] == 0
    assert f"ends {hits[True][0][0]} of them on an obstacle or off the road" in text
    config = (root / COST_DISCOUNT_C_RUNS[2][1] / "config.yaml").read_text()
    assert "gae_lambda: 0.95" in config and "minibatch_size: 512" in config
    assert (f"A collision 60 steps ahead now weighs {0.99 ** 60:.2f} in the cost-to-go the "
            f"critic estimates ({0.95 ** 60:.2f} at 0.95), and {(0.99 * 0.95) ** 60:.3f} "
            f"directly in its GAE target ({(0.95 * 0.95) ** 60:.3f} at 0.95)") in text

    def share(gamma: float, lam: float = 0.95) -> str:  # the λ-return's bootstrapped part
        return f"{gamma * (1 - lam) / (1 - gamma * lam):.2f}"

    assert f"γ(1 − λ) / (1 − γλ), {share(0.99)} at γ 0.99 against {share(0.95)} at 0.95" in text
    fits = [_collision_critic_row(root, label, run, 0.99)
            for label, run, _ in COST_DISCOUNT_C_RUNS[2:]]
    assert all(f["lead"][0]["predicted"] < f["lead"][0]["realised"] / 10 for f in fits)
    assert f"(the rows average {fits[0]['cost_steps']} and {fits[1]['cost_steps']} approaches)" \
        in text
    confident = [next(b for b in f["calibration"] if b["from"] == 0.1) for f in fits]
    assert all(b["to"] == 0.3 and b["predicted"] > b["realised"] for b in confident)
    assert (f"as high ({fits[0]['explained_variance']:.3f} and {fits[1]['explained_variance']:.3f}"
            f", correlation {fits[0]['correlation']:.3f} and {fits[1]['correlation']:.3f}), and "
            f"its correlation with the realised cost-to-go is only "
            f"{fits[0]['realised_correlation']:.3f} and {fits[1]['realised_correlation']:.3f}"
            ) in text
    assert (f"({confident[0]['predicted']:.3f} and {confident[1]['predicted']:.3f}, followed "
            f"by {confident[0]['realised']:.3f} and {confident[1]['realised']:.3f};") in text


STATE_SPREAD_RUNS = _crllk_c_trial_runs("state-dependent spread", "statestd")
"""CRLLK-C's state-dependent-spread trial's rows."""


def test_the_state_dependent_spread_rows_are_their_evaluations():
    """The rows (validation evaluations, late training J_coll, final λ_coll), the reverse
    direction's collisions and the updates' KL quoted in the prose."""

    root = REPO / "results/runs/pixels/obstacle_loop"
    text = " ".join(FINDINGS.split())
    hits, reverse, kl, blocked = {}, [], {}, {}
    off_road, late_coll, multipliers, rates = [], [], [], set()
    for label, run, sampled_name in STATE_SPREAD_RUNS:
        sampled, _, late, j_coll = _crllk_c_trial_row(root, label, run, sampled_name)
        trial = "statestd" in run
        assert bool(_model_setting(root / run, "state_dependent_std")) == trial
        hits.setdefault(trial, []).append(_endings(sampled))
        kl.setdefault(trial, []).append(sum(float(r["kl_approx"]) for r in late) / len(late))
        reverse.append(sampled["breakdown"]["by_direction"]["reverse"]["J_coll"])
        blocked.setdefault(trial, []).append(
            sampled["breakdown"]["by_direction"]["intended"]["J_clane"])
        if trial:
            off_road.append(sampled["terminations"].get("off_road", 0))
            late_coll.append(f"{sum(j_coll) / len(j_coll):.3f}")
            multipliers.append(f"{float(late[-1]['lambda_collision']):.1f}")
        rates.add(next(line for line in (root / run / "config.yaml").read_text().splitlines()
                       if line.strip().startswith("lr:")))
    assert (f"ended {hits[True][0]} and {hits[True][1]} of their 400 validation episodes on an "
            f"obstacle or off the road (against {hits[False][0]} and {hits[False][1]};") in text
    assert (f"(J_coll {reverse[2]:.3f} and {reverse[3]:.3f} there, against {reverse[0]:.3f} and "
            f"{reverse[1]:.3f})") in text
    assert (f"(against {hits[False][0]} and {hits[False][1]}; {off_road[0]} and {off_road[1]} of "
            "them off the road)") in text
    assert (f"still collided {late_coll[0]} and {late_coll[1]} per episode over iterations "
            f"400–489 with λ_coll at {multipliers[0]} and {multipliers[1]}") in text
    assert (f"(sampled {blocked[True][0]:.3f} and {blocked[True][1]:.3f} dm, against "
            f"{blocked[False][0]:.3f} and {blocked[False][1]:.3f})") in text
    assert max(blocked[True]) < min(blocked[False])
    assert len(rates) == 1  # "at the same learning rate"
    assert (f"(mean approximate KL over those iterations {kl[True][0]:.3f} and "
            f"{kl[True][1]:.3f}, against {kl[False][0]:.4f} and {kl[False][1]:.4f})") in text
    assert min(kl[True]) > 8 * max(kl[False])
