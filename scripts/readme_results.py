"""The README's results table and its peer comparison, written from the committed test
evaluations.

    python scripts/readme_results.py          # print them
    python scripts/readme_results.py --write  # put them into README.md between their markers

Each cell of the table is the mean over training seeds of J_clane (dm) / J_coll / J_R (m) of
the sampled policy on the test seed, from ``results/pixels/table1.json``, ``table_zigzag.json``
and ``table_obstacle_loop.json``, with how many seeds hold both constraints (on the point
estimate, then at the 95 % upper bound); below it, the same counts for the CRLLK agents'
deployed policies and, on ``obstacle_loop``, each constraint in the blocked direction alone.
The peer paragraph ranks, per map of ``results/state/peers.json``, every learner by its worst
seed's largest metric over its threshold, and says whether an OmniSafe learner beats CRLLK-D;
the traffic paragraph, per task of ``results/pixels/traffic.json``, each agent's seeds that
hold, its metrics, multipliers and collisions; the fleet paragraph, from
``results/pixels/fleet.json``, each agent's J_coll alone and in the fleet. A test checks that
the README holds exactly what this writes, and worked documents check the counts.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from crllk.evaluation.intervals import wilson_interval

REPO = Path(__file__).resolve().parents[1]
TABLES = {"small_loop": "table1.json", "zigzag": "table_zigzag.json",
          "obstacle_loop": "table_obstacle_loop.json"}
START, END = "<!-- results-table -->", "<!-- /results-table -->"
PEERS_START, PEERS_END = "<!-- peers-summary -->", "<!-- /peers-summary -->"
PEERS = REPO / "results" / "state" / "peers.json"
TRAFFIC_START, TRAFFIC_END = "<!-- traffic-summary -->", "<!-- /traffic-summary -->"
TRAFFIC = REPO / "results" / "pixels" / "traffic.json"
FLEET_START, FLEET_END = "<!-- fleet-summary -->", "<!-- /fleet-summary -->"
FLEET = REPO / "results" / "pixels" / "fleet.json"
MULTIPLIER_NAMES = {"lane": "λ_lane", "collision": "λ_coll", "headway": "λ_head"}


def results_table(results: Path = REPO / "results" / "pixels") -> str:
    """The Markdown table (one row per agent, one column per map: its mean metrics, the seeds
    that hold both constraints, and those that hold them at the 95 % upper bound), then what
    the CRLLK agents' deployed policies hold and the blocked direction of ``obstacle_loop``."""
    documents = {task: json.loads((results / name).read_text()) for task, name in TABLES.items()}
    agents = list(next(iter(documents.values()))["agents"])
    lines = ["| agent | " + " | ".join(f"`{task}`" for task in TABLES) + " |",
             "| --- |" + " --- |" * len(TABLES)]
    for agent in agents:
        cells = []
        for document in documents.values():
            entry = document["agents"][agent]
            held = sum(document["runs"][run]["satisfied"] for run in entry["runs"])
            bound = _held_at_bound(entry, document["thresholds"])
            cells.append(f"{entry['J_clane']['mean']:.3f} / {entry['J_coll']['mean']:.3f} / "
                         f"{entry['J_R']['mean']:.2f} ({held} of {len(entry['runs'])}; "
                         f"{bound} at the 95 % bound)")
        lines.append(f"| {agent} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n\n" + _deployed_and_blocked(documents)


def _held_at_bound(entry: dict, thresholds: dict) -> int:
    """Seeds whose 95 % intervals of J_clane and J_coll lie wholly within the thresholds."""
    intervals = entry["intervals"]
    return sum(lane[1] <= thresholds["lane"] and coll[1] <= thresholds["collision"]
               for lane, coll in zip(intervals["J_clane"], intervals["J_coll"], strict=True))


CRLLK_AGENTS = ("CRLLK-D", "CRLLK-C")
"""The learned-multiplier agents whose deployed policies and blocked direction are reported."""

DEPLOYED_NAMES = {"expected_duty": "expected duties", "expected_action": "expected action"}
"""How a table's ``mode.deployed`` entry names the deployed policy."""


def _deployed_and_blocked(documents: dict[str, dict]) -> str:
    """Two small tables: per CRLLK agent and map, the deployed policy's seeds that hold both
    constraints (point estimate, then 95 % upper bound); and on ``obstacle_loop``, per agent
    and policy, the seeds whose episodes started in the direction the obstacles block hold
    each constraint on the point estimate."""
    lines = ["| deployed policy | " + " | ".join(f"`{task}`" for task in documents) + " |",
             "| --- |" + " --- |" * len(documents)]
    for agent in CRLLK_AGENTS:
        modes = [document["agents"][agent]["mode"] for document in documents.values()]
        kinds = sorted({kind for mode in modes for kind in mode["deployed"]})
        cells = [f"{sum(mode['satisfied'])} of {len(mode['runs'])} "
                 f"({_held_at_bound(mode, document['thresholds'])} at the 95 % bound)"
                 for mode, document in zip(modes, documents.values(), strict=True)]
        name = ", ".join(DEPLOYED_NAMES.get(kind, kind) for kind in kinds)
        lines.append(f"| {agent} ({name}) | " + " | ".join(cells) + " |")
    document = documents["obstacle_loop"]
    thresholds = document["thresholds"]
    rows, episodes = [], set()
    for agent in CRLLK_AGENTS:
        entry = document["agents"][agent]
        for name, source in (("sampled", entry), ("deployed", entry["mode"])):
            blocked = [seed["intended"] for seed in source["by_direction"]]
            episodes |= {seed["episodes"] for seed in blocked}
            coll = sum(seed["J_coll"] <= thresholds["collision"] for seed in blocked)
            lane = sum(seed["J_clane"] <= thresholds["lane"] for seed in blocked)
            lanes = [seed["J_clane"] for seed in blocked]
            rows.append(f"| {agent}, {name} | {coll} of {len(blocked)} | {lane} of "
                        f"{len(blocked)} ({min(lanes):.2f}–{max(lanes):.2f} dm) |")
    fewest, most = min(episodes), max(episodes)
    count = str(fewest) if fewest == most else f"{fewest}–{most}"
    clean = wilson_interval(0, fewest)[1]  # the 95 % upper bound of 0 collisions in them
    return "\n".join([
        *lines, "",
        f"On `obstacle_loop`, the episodes that start in the direction the obstacles block "
        f"({count} of each run's 400), seeds that hold each constraint on the point estimate "
        f"(at the 95 % bound none could hold J_coll: 0 collisions in {fewest} episodes still "
        f"allow {clean:.3f}):", "",
        f"| agent, policy | J_coll ≤ {thresholds['collision']} | J_clane ≤ {thresholds['lane']} "
        "dm |", "| --- | --- | --- |", *rows])


def _worst(entry: dict, thresholds: dict) -> tuple[float, float, float]:
    """The largest metric/threshold over seeds and both constraints (at most 1: every seed
    holds both), and the largest J_clane and J_coll over seeds."""
    lane, coll = max(entry["J_clane"]["values"]), max(entry["J_coll"]["values"])
    return max(lane / thresholds["lane"], coll / thresholds["collision"]), lane, coll


def peers_summary(path: Path = PEERS) -> str:
    """One paragraph from the peer comparison: per map every learner by its worst seed's
    largest metric/threshold (at most 1: both constraints hold on every seed), tightest
    first, and whether an OmniSafe learner does better than CRLLK-D on some map."""
    document = json.loads(path.read_text())
    thresholds = document["thresholds"]
    sentences, better = [], []
    for task, table in document["maps"].items():
        ratios = {name: _worst(entry, thresholds)[0] for name, entry in table["learners"].items()}
        ranked = sorted(ratios, key=lambda name: ratios[name])
        sentences.append(f"on `{task}` " + ", ".join(f"{name} {ratios[name]:.2f}"
                                                      for name in ranked))
        better += [f"{name} on `{task}`" for name in ranked if name.startswith("OmniSafe")
                   and ratios[name] < ratios["CRLLK-D"]]
    verdict = ("Better than CRLLK-D: " + ", ".join(better) if better else
               "No OmniSafe learner does better than CRLLK-D on any map")
    return ("From state, crllk's learners beside OmniSafe's PPOLag and CPPOPID on the same "
            f"tasks ({len(document['settings']['seeds'])} seeds each, "
            f"{document['settings']['episodes']} test episodes per run, "
            "[Peer libraries](docs/results/peers.md)), each learner by its worst seed's largest "
            "metric over its threshold (at most 1: both constraints hold on every seed), "
            "tightest first: " + "; ".join(sentences) + f". {verdict}.")


def _span(values: list[float], digits: int) -> str:
    """``low–high`` of ``values`` (one value alone)."""
    low, high = min(values), max(values)
    return f"{low:.{digits}f}" if f"{low:.{digits}f}" == f"{high:.{digits}f}" else \
        f"{low:.{digits}f}–{high:.{digits}f}"


def _agent_sentence(agent: str, entry: dict) -> str:
    """An agent's seeds that hold every constraint (the runs' own verdicts), its metrics' spans
    over seeds, its multipliers (fixed weights for the PPO agents, learned for the others) and
    what its test episodes collided with."""
    runs = len(entry["runs"])
    held = f"{sum(entry['satisfied'])} of {runs} seeds hold every constraint"
    if "mode" in entry:
        deployed = ("deployed, as expected duties"
                    if "expected_duty" in entry["mode"].get("deployed", ()) else
                    "in the deployed mode")
        held += f" ({sum(entry['mode']['satisfied'])} of {runs} {deployed})"
    metrics = ", ".join(f"{c['metric']} {_span(entry[c['metric']]['values'], 3)}"
                        for c in entry["constraints"])
    kind = "fixed" if agent.startswith("PPO") else "learned"
    weights = ", ".join(f"{MULTIPLIER_NAMES.get(n, n)} "
                        f"{_span([m[n] for m in entry['multipliers'] if n in m], 1)}"
                        for n in (c["name"] for c in entry["constraints"])
                        if any(n in m for m in entry["multipliers"]))
    weights = f"{kind} {weights}; " if weights else ""
    kinds: dict[str, int] = {}
    for community in entry["community"]:
        for name, count in ((community or {}).get("collisions_by_kind") or {}).items():
            kinds[name] = kinds.get(name, 0) + count
    episodes = sum((c or {}).get("episodes", 0) for c in entry["community"])
    hits = ", ".join(f"{name} {count}" for name, count in kinds.items()) or "nothing"
    return (f"**{agent}** {held}, {metrics} ({weights}its {episodes} sampled test "
            f"episodes hit: {hits})")


def traffic_summary(path: Path = TRAFFIC) -> str:
    """One paragraph from the traffic experiment: per task and agent, the seeds that hold,
    the metrics, the multipliers (learned or fixed) and what the collisions hit."""
    document = json.loads(path.read_text())
    settings = document["settings"]
    sentences = []
    for task, block in document["tasks"].items():
        agents = "; ".join(_agent_sentence(agent, entry)
                           for agent, entry in block["agents"].items())
        sentences.append(f"on `{task}`, {agents}")
    return (f"With traffic, from the camera ({settings['episodes']} test episodes per run, "
            "[Traffic](docs/results/traffic.md)): "
            + "; ".join(sentences) + ".")


def fleet_summary(path: Path = FLEET) -> str:
    """One paragraph from the fleet experiment: per agent, its seeds' J_coll and J_clane alone
    among the scripted traffic and as one of the robots its policy drives, and how many of the
    fleet's robot-episodes hold every constraint."""
    document = json.loads(path.read_text())
    settings = document["settings"]
    sentences = []
    for agent, block in document["agents"].items():
        alone, fleet = block["alone"], block["fleet"]
        robot_episodes = sum((c or {}).get("episodes", 0) for c in fleet["community"])
        kinds: dict[str, int] = {}
        for community in fleet["community"]:
            for name, count in ((community or {}).get("collisions_by_kind") or {}).items():
                kinds[name] = kinds.get(name, 0) + count
        hits = ", ".join(f"{name} {count}" for name, count in kinds.items()) or "nothing"
        sentences.append(
            f"**{agent}** J_coll {_span(alone['J_coll']['values'], 3)} alone, "
            f"{_span(fleet['J_coll']['values'], 3)} in the fleet, J_clane "
            f"{_span(alone['J_clane']['values'], 3)} and {_span(fleet['J_clane']['values'], 3)}"
            f" ({sum(fleet['satisfied'])} of {len(fleet['runs'])} seeds hold every constraint "
            f"in the fleet; its {robot_episodes} robot-episodes hit: {hits})")
    return (f"Every robot driven by the policy, on `{document['task']}` "
            f"({settings['robots']} robots, {settings['fleet_episodes'] * settings['robots']} "
            "robot-episodes per run on the test seed, [Every robot driven by the policy]"
            "(docs/results/fleet.md)): " + "; ".join(sentences) + ".")


def _replace(text: str, start: str, end: str, block: str) -> str:
    head, rest = text.split(start, 1)
    tail = rest.split(end, 1)[1]
    return f"{head}{start}\n{block}\n{end}{tail}"


def write(readme: Path = REPO / "README.md") -> None:
    text = _replace(readme.read_text(), START, END, results_table())
    if PEERS.is_file():
        text = _replace(text, PEERS_START, PEERS_END, peers_summary())
    if TRAFFIC.is_file():
        text = _replace(text, TRAFFIC_START, TRAFFIC_END, traffic_summary())
    if FLEET.is_file():
        text = _replace(text, FLEET_START, FLEET_END, fleet_summary())
    readme.write_text(text)


if __name__ == "__main__":
    if sys.argv[1:] == ["--write"]:
        write()
    else:
        print(results_table())
        if PEERS.is_file():
            print(peers_summary())
        if TRAFFIC.is_file():
            print(traffic_summary())
        if FLEET.is_file():
            print(fleet_summary())
