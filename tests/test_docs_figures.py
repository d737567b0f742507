"""Figures quoted in the prose of the README and of the documentation site are the committed
results they name. The tables themselves are included as the experiments wrote them
(``tests/test_results.py``); these checks cover the sentences beside them, and fail on a new
figure of a checked kind (a "% farther", a run time range) until it is checked too."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest
from docs_pages import DOCS, page, pages, prose

from crllk.evaluation.intervals import wilson_interval

REPO = Path(__file__).resolve().parents[1]
STATE = REPO / "results" / "state"
TABLES = {"small_loop": "table1.json", "zigzag": "table_zigzag.json",
          "obstacle_loop": "table_obstacle_loop.json"}


def _travel(task: str) -> dict[str, float]:
    document = json.loads((STATE / TABLES[task]).read_text())
    travel = {agent: entry["J_R"]["mean"] for agent, entry in document["agents"].items()}
    return {**travel, "follower": document["follower"]["J_R"]}


def _farther(a: float, b: float) -> str:
    return f"{round(100 * (a / b - 1))} % farther"


def _state_sentences() -> list[str]:
    """Every "% farther" of the From state page, written from the state tables."""
    small, zigzag, obstacles = (_travel(task) for task in TABLES)
    lane = {agent: entry["J_clane"]["mean"] for agent, entry in
            json.loads((STATE / TABLES["small_loop"]).read_text())["agents"].items()}
    return [
        f"CRLLK-C travels {_farther(small['CRLLK-C'], small['CRLLK-D'])} than CRLLK-D and "
        f"{_farther(small['CRLLK-C'], small['follower'])} than the scripted follower.",
        f"CRLLK-D deviates {lane['CRLLK-D']:.2f} dm against {lane['PPO-D']:.2f} for PPO-D and "
        f"travels {_farther(small['CRLLK-D'], small['PPO-D'])}; CRLLK-C {lane['CRLLK-C']:.2f} "
        f"against {lane['PPO-C']:.2f} dm, {_farther(small['CRLLK-C'], small['PPO-C'])}.",
        f"CRLLK-D travels {_farther(zigzag['CRLLK-D'], zigzag['PPO-D'])} than PPO-D, CRLLK-C "
        f"{_farther(zigzag['CRLLK-C'], zigzag['PPO-C'])} than PPO-C and "
        f"{_farther(zigzag['CRLLK-C'], zigzag['CRLLK-D'])} than CRLLK-D.",
        f"CRLLK-C travels {_farther(obstacles['CRLLK-C'], obstacles['CRLLK-D'])} than CRLLK-D "
        f"and {_farther(obstacles['CRLLK-C'], obstacles['PPO-C'])} than PPO-C.",
    ]


def test_the_state_page_s_comparisons_are_the_state_tables():
    text = prose("results/state.md")
    for sentence in _state_sentences():
        assert sentence in text


def test_the_state_page_s_obstacle_loop_figures_are_the_runs():
    """From state on obstacle_loop: the discrete agents' test J_coll, sampled and deployed,
    CRLLK-D's final λ_coll, and the replaced former-default runs' figures."""
    runs = REPO / "results/runs/state/obstacle_loop"

    def document(run: Path, name: str) -> dict:
        return json.loads((run / f"{name}.json").read_text())

    def j_coll(runs_: list[Path], name: str) -> list[float]:
        return [document(run, name)["summary"]["J_coll"] for run in runs_]

    def listed(values: list[float], digits: int = 3) -> str:
        words = [f"{value:.{digits}f}" for value in values]
        return ", ".join(words[:-1]) + " and " + words[-1]

    text = prose("results/state.md")
    ours = [runs / f"CRLLK-D-a0.5-seed{seed}" for seed in (0, 1, 2)]
    sampled, deployed = j_coll(ours, "test"), j_coll(ours, "test-mode")
    assert max(sampled + deployed) <= 0.02
    multipliers = [document(run, "test")["source"]["multipliers"]["collision"] for run in ours]
    assert (f"CRLLK-D's sampled J_coll, {listed(sampled)} on seeds 0, 1 and 2 (its learned "
            f"λ_coll ended at {listed(multipliers, 1)})") in text
    assert f"collides less ({listed(deployed)})" in text
    fixed = [runs / f"PPO-D-a0.5-seed{seed}" for seed in (0, 1)]
    assert min(j_coll(fixed, "test")) > 0.02
    assert (f"misses α2 sampled on both seeds (J_coll {listed(j_coll(fixed, 'test'))}; "
            f"deployed {listed(j_coll(fixed, 'test-mode'))})") in text
    former = [runs.parent / "replaced/obstacle_loop" / f"CRLLK-D-a0.5-seed{seed}"
              for seed in (0, 1)]

    def endings(runs_: list[Path], name: str) -> str:
        counts = [int(sum(e["cost_collision"] for e in document(run, name)["episodes"]))
                  for run in runs_]
        return f"{counts[0]} and {counts[1]}"

    assert (f"{endings(ours[:2], 'test')} of 400 episodes on seeds 0 and 1, against "
            f"{endings(former, 'test')}") in text
    upper = [wilson_interval(round(400 * j), 400)[1] for j in j_coll(former, "test")]
    assert upper[0] > 0.02 >= upper[1]  # "the former seed 1 held α2 at the 95 % upper bound"
    assert all(wilson_interval(round(400 * j), 400)[1] > 0.02 for j in sampled)
    assert (f"ended {endings(former, 'test-mode')} of 400 episodes on an obstacle or off the "
            "road") in text


def test_every_farther_in_the_documentation_is_checked():
    """A new "N % farther" anywhere fails until a test writes it from the results."""
    checked = sum(len(re.findall(r"\d+ % farther", s)) for s in _state_sentences())
    quoted = sum(len(re.findall(r"\d+ % farther", prose(name))) for name in _documents())
    assert quoted == checked


def _wall_ranges() -> set[str]:
    """The training wall-time ranges the experiments wrote into their tables."""
    found = set()
    for table in REPO.glob("results/*/*.md"):
        found |= set(re.findall(r"training wall time (\d+\.\d–\d+\.\d) min per run",
                                table.read_text()))
    return found


ELSEWHERE = {
    "2.3–4.4": "the fixed-weight sweep from state (its runs' metrics.csv, before the sweep's "
               "Markdown gave wall times)",
    "24.9–28.4": "the four randomised runs of the robustness experiment, with five evaluations",
    "15–20": "the robustness conditions rendered at 640×480, per 100 episodes",
    "4.5–7.5": "make test from a fresh clone (Development)",
}
"""Time ranges quoted from measurements the experiments do not tabulate, with their source.
A new range fails until it is an experiment's or added here after checking it."""


def _documents() -> list[str]:
    return ["README.md", *pages()]


def test_every_time_range_is_an_experiment_s_or_known():
    generated = _wall_ranges()
    for name in _documents():
        if name == "findings.md":  # each trial's time is stated with its command there
            continue
        for low, high in re.findall(r"(\d+(?:\.\d+)?)–(\d+(?:\.\d+)?) min\b", prose(name)):
            quoted = f"{low}–{high}"
            assert quoted in generated or quoted in ELSEWHERE, (name, quoted)


def test_the_evaluation_page_s_sampled_and_mode_figures_are_the_runs():
    """The validation evaluations of CRLLK-D on obstacle_loop, sampled and from its most
    probable action (``eval-mode.json``, written when that was the deployed policy)."""
    root = REPO / "results/runs/pixels/obstacle_loop"  # the former default's runs
    sampled, mode = ([json.loads((root / f"CRLLK-D-curve1-a0.5-seed{s}" / f"{name}.json")
                                 .read_text())["summary"] for s in (0, 1)]
                     for name in ("eval", "eval-mode"))
    text = prose("evaluation.md")
    assert (f"gave J_coll {sampled[0]['J_coll']:.2f} / {sampled[1]['J_coll']:.2f} sampled "
            f"and {mode[0]['J_coll']:.2f} / {mode[1]['J_coll']:.2f} from its most probable "
            f"action (seeds 0 / 1), with J_clane {sampled[0]['J_clane']:.3f} / "
            f"{sampled[1]['J_clane']:.3f} dm sampled and {mode[0]['J_clane']:.3f} / "
            f"{mode[1]['J_clane']:.3f} dm from it") in text
    assert not any("deployed" in json.loads((root / f"CRLLK-D-curve1-a0.5-seed{s}" /
                                             "eval-mode.json").read_text())["evaluation"]
                   for s in (0, 1))
    assert all(m["J_coll"] <= s["J_coll"] and m["J_clane"] > s["J_clane"]
               for s, m in zip(sampled, mode, strict=True))


@pytest.mark.parametrize("stale", ["0.06 / 0.08", "35–80 min per run", "44 % farther"])
def test_the_stale_figures_are_gone(stale):
    for name in _documents():
        assert stale not in prose(name), name


def test_the_readme_s_results_table_is_what_the_script_writes():
    spec = importlib.util.spec_from_file_location("readme_results",
                                                  REPO / "scripts" / "readme_results.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    readme = page("README.md")
    block = readme.split(module.START, 1)[1].split(module.END, 1)[0]
    assert block.strip() == module.results_table()
    if module.PEERS.is_file():  # the peer comparison's paragraph, once it is committed
        block = readme.split(module.PEERS_START, 1)[1].split(module.PEERS_END, 1)[0]
        assert block.strip() == module.peers_summary()
    if module.TRAFFIC.is_file():  # the traffic paragraph, once the experiment is committed
        assert module.TRAFFIC_START in readme and module.TRAFFIC_END in readme
        block = readme.split(module.TRAFFIC_START, 1)[1].split(module.TRAFFIC_END, 1)[0]
        assert block.strip() == module.traffic_summary()
    if module.FLEET.is_file():  # the fleet paragraph, once the experiment is committed
        assert module.FLEET_START in readme and module.FLEET_END in readme
        block = readme.split(module.FLEET_START, 1)[1].split(module.FLEET_END, 1)[0]
        assert block.strip() == module.fleet_summary()


def test_the_peers_paragraph_worked_example(tmp_path):
    """Learners ranked by their worst seed's largest metric/threshold; an OmniSafe learner
    below CRLLK-D is named."""
    spec = importlib.util.spec_from_file_location("readme_results",
                                                  REPO / "scripts" / "readme_results.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def learner(lanes, colls):
        return {"J_clane": {"values": lanes}, "J_coll": {"values": colls}}

    path = tmp_path / "peers.json"
    path.write_text(json.dumps({
        "thresholds": {"lane": 0.5, "collision": 0.02},
        "settings": {"seeds": [0, 1], "episodes": 400},
        "maps": {"small_loop": {"learners": {
            "CRLLK-D": learner([0.2, 0.25], [0.0, 0.01]),        # worst 0.01/0.02 = 0.50
            "OmniSafe PPOLag": learner([0.1, 0.2], [0.0, 0.0]),  # worst 0.2/0.5 = 0.40
            "CRLLK-C": learner([0.3, 0.1], [0.04, 0.0])}}}}))    # worst 0.04/0.02 = 2.00
    assert module.peers_summary(path).endswith(
        "tightest first: on `small_loop` OmniSafe PPOLag 0.40, CRLLK-D 0.50, CRLLK-C 2.00. "
        "Better than CRLLK-D: OmniSafe PPOLag on `small_loop`.")


def test_the_traffic_paragraph_worked_example(tmp_path):
    """Each agent's seeds that hold, spans of its metrics, its multipliers and what it hit,
    from a hand-made document (one seed holds, one misses J_coll)."""
    spec = importlib.util.spec_from_file_location("readme_results",
                                                  REPO / "scripts" / "readme_results.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    constraints = [{"name": "lane", "metric": "J_clane"},
                   {"name": "collision", "metric": "J_coll"}]
    entry = {"runs": ["CRLLK-D-a0.5-seed0", "CRLLK-D-a0.5-seed1"], "constraints": constraints,
             "J_clane": {"values": [0.31, 0.27]}, "J_coll": {"values": [0.01, 0.05]},
             "satisfied": [True, False],
             "multipliers": [{"lane": 0.0, "collision": 12.54}, {"lane": 0.0, "collision": 20.0}],
             "community": [{"episodes": 400, "collisions_by_kind": {"vehicle": 4}},
                           {"episodes": 400, "collisions_by_kind": {"vehicle": 16,
                                                                    "pedestrian": 4}}]}
    entry["mode"] = {**entry, "J_coll": {"values": [0.0, 0.0]}, "satisfied": [True, True]}
    fixed = {**entry, "runs": entry["runs"][:1], "J_clane": {"values": [0.2]},
             "J_coll": {"values": [0.3]}, "satisfied": [False],
             "multipliers": [{"lane": 1.0, "collision": 5.0}],
             "community": [{"episodes": 400, "collisions_by_kind": {}}]}
    del fixed["mode"]
    path = tmp_path / "traffic.json"
    path.write_text(json.dumps({"settings": {"episodes": 400}, "tasks": {"traffic_loop": {
        "thresholds": {"lane": 0.5, "collision": 0.02},
        "agents": {"CRLLK-D": entry, "PPO-D": fixed}}}}))
    assert module.traffic_summary(path) == (
        "With traffic, from the camera (400 test episodes per run, "
        "[Traffic](docs/results/traffic.md)): on `traffic_loop`, **CRLLK-D** 1 of 2 seeds hold "
        "every constraint (2 of 2 in the deployed mode), J_clane 0.270–0.310, J_coll "
        "0.010–0.050 (learned λ_lane 0.0, λ_coll 12.5–20.0; its 800 sampled test episodes hit: "
        "vehicle 20, pedestrian 4); **PPO-D** 0 of 1 seeds hold every constraint, J_clane 0.200, "
        "J_coll 0.300 (fixed λ_lane 1.0, λ_coll 5.0; its 400 sampled test episodes hit: nothing).")


def test_the_fleet_paragraph_worked_example(tmp_path):
    """Per agent: J_coll and J_clane alone and in the fleet over seeds, the seeds that hold in
    the fleet and what its robot-episodes hit."""
    spec = importlib.util.spec_from_file_location("readme_results",
                                                  REPO / "scripts" / "readme_results.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def entry(colls, lanes, satisfied, community):
        return {"J_coll": {"values": colls}, "J_clane": {"values": lanes},
                "satisfied": satisfied, "runs": ["a", "b"], "community": community}

    path = tmp_path / "fleet.json"
    path.write_text(json.dumps({
        "task": "traffic_loop", "settings": {"robots": 4, "fleet_episodes": 100},
        "agents": {"CRLLK-D": {
            "alone": entry([0.05, 0.045], [0.15, 0.144], [False, False], [{}, {}]),
            "fleet": entry([0.03, 0.0125], [0.2, 0.21], [False, True],
                           [{"episodes": 400, "collisions_by_kind": {"vehicle": 12}},
                            {"episodes": 400, "collisions_by_kind": {"vehicle": 5}}])}}}))
    assert module.fleet_summary(path) == (
        "Every robot driven by the policy, on `traffic_loop` (4 robots, 400 robot-episodes per "
        "run on the test seed, [Every robot driven by the policy](docs/results/fleet.md)): "
        "**CRLLK-D** J_coll 0.045–0.050 alone, 0.013–0.030 in the fleet, J_clane 0.144–0.150 "
        "and 0.200–0.210 (1 of 2 seeds hold every constraint in the fleet; its 800 "
        "robot-episodes hit: vehicle 17).")


def test_every_results_file_named_exists():
    """A page that names a committed file under results/ names one that is there."""
    for name in _documents():
        raw = (REPO / name).read_text() if name == "README.md" else (DOCS / name).read_text()
        pending = re.findall(r"<!-- include-if-present (\S+) -->", raw)
        for path in re.findall(r"`(results/[^`\s]+)`", page(name)):
            if any(c in path for c in "<>*{}") or "..." in path or path in pending:
                continue
            assert (REPO / path).exists() or list(REPO.glob(path + "*")), (name, path)


def test_the_sweep_s_gains_are_the_sweep_s():
    """CRLLK-D's margin over the best fixed pair that holds, per map, as the From state page
    quotes it, from ``results/state/sweep.json``."""
    maps = json.loads((STATE / "sweep.json").read_text())["maps"]
    parts = []
    for task, entry in maps.items():
        ours, best = entry["crllk"]["J_R"]["mean"], entry["best_feasible_fixed"]["J_R"]["mean"]
        parts.append(f"{ours - best:.2f} m ({round(100 * (ours - best) / best)} %) on `{task}`")
    quoted = f"by {parts[0]}, {parts[1]} and {parts[2]}"
    assert quoted in prose("results/state.md")


def test_the_teacher_s_figures_on_the_training_page_are_its_evaluations():
    """The privileged teacher on obstacle_loop at its default margin and at 4 cm."""
    runs = {margin: json.loads((REPO / f"results/scripted/teacher-obstacle_loop-margin{margin}"
                                ".json").read_text())["teacher"]["summary"]
            for margin in ("0.07", "0.04")}
    default, close = runs["0.07"], runs["0.04"]
    assert (f"J_coll {default['J_coll']:g}, J_clane {default['J_clane']:.3f} dm, J_R "
            f"{default['J_R']:.2f} m; {close['J_clane']:.3f} dm and {close['J_R']:.2f} m at 4 cm"
            ) in prose("training.md")


def test_the_state_page_s_follower_is_the_tables():
    cells = []
    for task in ("zigzag", "obstacle_loop"):
        f = json.loads((STATE / TABLES[task]).read_text())["follower"]
        cells.append(f"{f['J_clane']:.3f} / {f['J_coll']:.2f} / {f['J_R']:.2f} on `{task}`")
    assert f"through the same episodes: {cells[0]}, {cells[1]}." in prose("results/state.md")


def test_in_short_s_pilot_parity_is_the_parity_table_s():
    """The README's (and the home page's) range of agreement is the Sim-to-real table's, over
    the policies trained for the robot at 8× supersampling."""
    rows = [line for line in page("sim-to-real.md").splitlines()
            if line.startswith("| `small_loop`, randomised") and "supersample=8" in line]
    assert len(rows) == 2
    shares = [float(v) for row in rows for v in re.findall(r"\*\*([\d.]+) %\*\*", row)]
    assert len(shares) == 6
    low, high = min(shares), max(shares)
    span = f"{high:g}" if low == high else f"{low:.1f}–{high:g}"
    for where in ("README.md", "index.md"):
        assert f"on {span} % of frames (policies trained for the robot at 8× " \
            "supersampling, two seeds)" in prose(where)


def test_the_traffic_sentence_is_what_the_runs_show():
    """In short's traffic sentence: on both tasks every run of both discrete agents misses α2
    on the test seed; CRLLK-D's λ_coll ends above PPO-D's fixed collision weight on every run
    while its λ_lane and λ_head end near zero (below 0.1, where PPO-D keeps 1); the scripted
    teacher answering in the same discrete actions collides too, in continuous actions still
    hits crossing duckies, and in stoppable actions holds α2 on both tasks; CRLLK-D's mean
    J_coll is within a quarter either way of PPO-D's ("about as often")."""
    document = json.loads((REPO / "results/pixels/traffic.json").read_text())
    text = " ".join(page("README.md").split())
    assert "neither discrete agent holds α2 on either task, on any seed" in text
    assert "yet the agent collides about as often as with the fixed weights" in text
    for task, block in document["tasks"].items():
        crllk, ppo = block["agents"]["CRLLK-D"], block["agents"]["PPO-D"]
        bound = block["thresholds"]["collision"]
        assert all(v > bound for entry in (crllk, ppo) for v in entry["J_coll"]["values"]), task
        fixed = {m["collision"] for m in ppo["multipliers"]}
        assert len(fixed) == 1 and all(m["collision"] > max(fixed) for m in crllk["multipliers"])
        for name in ("lane", "headway"):
            assert all(m.get(name, 0.0) < 0.1 for m in crllk["multipliers"]), (task, name)
            assert all(m.get(name, 1.0) == 1.0 for m in ppo["multipliers"]), (task, name)
        assert block["teacher"]["discrete"]["J_coll"]["values"][0] > 0.0, task
        assert block["teacher"]["stoppable"]["J_coll"]["values"][0] <= bound, task
        ratio = (sum(crllk["J_coll"]["values"]) / len(crllk["J_coll"]["values"])) / (
            sum(ppo["J_coll"]["values"]) / len(ppo["J_coll"]["values"]))
        assert 0.75 <= ratio <= 1.0 / 0.75, (task, ratio)
    pedestrians = document["tasks"]["pedestrian_loop"]
    assert pedestrians["teacher"]["continuous"]["J_coll"]["values"][0] > \
        pedestrians["thresholds"]["collision"]
    assert "answering in them, the teacher still hits crossing duckies" in text
    assert "(`action=stoppable`), it holds α2 on both tasks" in text
    stoppable = {task: block["agents"]["CRLLK-C-stoppable"]
                 for task, block in document["tasks"].items()}
    assert "CRLLK-C learning in these actions holds every constraint on `traffic_loop` on all " \
        "three seeds, sampled and deployed" in text
    traffic = stoppable["traffic_loop"]
    assert len(traffic["satisfied"]) == 3 and all(traffic["satisfied"])
    assert len(traffic["mode"]["satisfied"]) == 3 and all(traffic["mode"]["satisfied"])
    hits_text = ("On `pedestrian_loop` it still misses α2 on every seed: it hits crossing "
                 "duckies in ")
    assert hits_text in text
    pedestrian = stoppable["pedestrian_loop"]
    bound = document["tasks"]["pedestrian_loop"]["thresholds"]["collision"]
    assert all(v > bound for v in pedestrian["J_coll"]["values"])
    assert len(pedestrian["J_coll"]["values"]) == 3
    entries = (pedestrian, pedestrian["mode"])
    hit_shares = [c["collisions_by_kind"].get("pedestrian", 0) / c["episodes"]
                  for entry in entries for c in entry["community"]]
    assert (f"{hits_text}{round(100 * min(hit_shares))}–{round(100 * max(hit_shares))} % of "
            "episodes, and one seed also leaves the road in") in text
    off_road = [[t.get("off_road", 0) / sum(t.values()) for t in entry["terminations"]]
                for entry in entries]
    leaving = [k for k in range(3) if all(0.05 < shares[k] < 0.15 for shares in off_road)]
    assert len(leaving) == 1
    assert all(shares[k] < 0.01 for shares in off_road for k in range(3) if k not in leaving)
    seed_shares = [round(100 * shares[leaving[0]]) for shares in off_road]
    assert (f"leaves the road in {min(seed_shares)}–{max(seed_shares)} % of them (sampled and "
            "deployed)") in text
    terminations = pedestrian["terminations"][leaving[0]]
    results_page = " ".join(page("results/traffic.md").split())
    assert (f"on seed {leaving[0]}, by leaving the road ({terminations['off_road']} of its "
            f"{sum(terminations.values())} sampled test episodes") in results_page


def test_how_the_pedestrian_seed_leaves_the_road_is_its_endings():
    """The results page's description of CRLLK-C-stoppable seed 1 leaving the road on
    pedestrian_loop is that run's ``endings.json`` (100 validation episodes, sampled)."""
    import statistics

    run = REPO / "results/runs/pixels/pedestrian_loop/CRLLK-C-stoppable-a0.5-seed1"
    document = json.loads((run / "endings.json").read_text())
    assert document["seed"] == 1_000_000 and not document["deterministic"]
    assert document["summary"]["episodes"] == 100 and document["seconds"] == 2.0
    off = [e for e in document["endings"] if e["termination"] == "off_road"]
    straight = [e for e in off if e["tile_kind"] == "straight"]
    top_row = [e for e in straight if e["tile"][1] == 1]
    lateral = [100 * e["mean_lateral"] for e in off]
    low = statistics.median(e["heading_error_deg"][0] for e in off)
    high = statistics.median(e["heading_error_deg"][1] for e in off)
    swings = [e["swings"] for e in off]
    text = " ".join(page("results/traffic.md").split())
    assert (f"{len(off)} of them ended off the road, {len(straight)} on straight tiles "
            f"({len(top_row)} on the top row)") in text
    final = [100 * e["final_lateral"] for e in off]
    assert (f"drove on average {min(lateral):.1f}–{max(lateral):.1f} cm right of its lane "
            f"centre and ended {min(final):.1f}–{max(final):.1f} cm right of it") in text
    assert min(final) > 0  # the right side
    assert f"between about −{-round(low)}° and +{round(high)}°" in text
    assert f"its turn changing side {min(swings)} to {max(swings)} times" in text


def test_the_parity_table_is_the_committed_parity_output():
    """Sim-to-real's parity table, row by row, is ``results/pixels/parity.txt`` (the runs in
    the table's order, the share of frames per map in its column order)."""
    lines = (REPO / "results/pixels/parity.txt").read_text().splitlines()
    runs: list[list[str]] = []
    for line in lines:
        if line.startswith("== "):
            runs.append([])
        elif runs and ": the same command on " in line:
            runs[-1].append(re.search(r"\(([\d.]+) %\)", line).group(1))
    rows = [line for line in page("sim-to-real.md").splitlines()
            if line.startswith(("| `small_loop`, randomised", "| `zigzag`, "))]
    assert len(rows) == len(runs) == 7
    for row, shares in zip(rows, runs, strict=True):
        assert re.findall(r"([\d.]+) %", row) == shares, row
    text = prose("sim-to-real.md")
    default = [float(v) for shares in runs[2:] for v in shares]
    assert f"on {min(default):.1f}–{max(default):.1f} % of frames" in text


def test_the_deployed_and_blocked_tables_worked_example():
    """Seeds count at the 95 % bound only when both upper ends are within the thresholds; the
    blocked direction counts each constraint on its own, for the sampled and deployed
    policies, and names the deployed policy by its kind."""
    spec = importlib.util.spec_from_file_location("readme_results",
                                                  REPO / "scripts" / "readme_results.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    thresholds = {"lane": 0.5, "collision": 0.02}

    def policy(satisfied, lane_upper, coll_upper, blocked):
        return {"runs": ["a", "b"], "satisfied": satisfied, "deployed": ["expected_duty"],
                "intervals": {"J_clane": [[0.1, u] for u in lane_upper],
                              "J_coll": [[0.0, u] for u in coll_upper]},
                "by_direction": [{"intended": {"episodes": 160, "J_clane": lane,
                                               "J_coll": coll}} for lane, coll in blocked]}

    sampled = policy([True, True], [0.4, 0.6], [0.019, 0.01], [(0.7, 0.01), (0.45, 0.03)])
    deployed = policy([True, False], [0.4, 0.4], [0.02, 0.021], [(0.6, 0.0), (0.5, 0.02)])
    assert module._held_at_bound(sampled, thresholds) == 1  # the second seed's lane: 0.6
    assert module._held_at_bound(deployed, thresholds) == 1  # 0.021 > 0.02
    document = {"thresholds": thresholds,
                "agents": {a: {**sampled, "mode": deployed} for a in module.CRLLK_AGENTS}}
    text = module._deployed_and_blocked({"obstacle_loop": document})
    assert "| CRLLK-D (expected duties) | 1 of 2 (1 at the 95 % bound) |" in text
    assert "| CRLLK-C, sampled | 1 of 2 | 1 of 2 (0.45–0.70 dm) |" in text
    assert "| CRLLK-C, deployed | 2 of 2 | 1 of 2 (0.50–0.60 dm) |" in text
    assert "(160 of each run's 400)" in text and "in 160 episodes still allow 0.023" in text
