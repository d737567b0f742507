"""``python -m crllk.experiments realmaps``: maps nobody tuned on. CRLLK-D, its configuration
unchanged, trained from pixels on two real Duckietown map files and judged on the test seed
per map and seed (sampled policy and deployed mode), with why each run that misses does.

The maps were chosen by measuring every single-file map of ``tests/data/real_maps/`` (road
tiles, intersection tiles, and objects on the road as :class:`~crllk.maps.obstacles.
ObstacleIndex` projects them onto the lanes), leaving out the ones ours derive from
(``loop_obstacles``, ``loop_pedestrians``, ``loop_dyn_duckiebots``, ``small_loop*``,
``zigzag*``):

- ``regress_4way_adam`` (7 x 7 tiles, 21 road tiles with four 3-way and one 4-way
  intersection, 19 objects): the only other map with objects in a driving lane. Six stand on the
  road within a lane's width (two barriers, a cone, two duckies, a building's corner); the two
  barriers come within 0.1 m of a lane centre, so they block a lane (the trainer's encounter
  starts face them): one covers the whole west-bound lane of the bottom row (-0.11 to +0.17 m
  from its centre), the other reaches 0.10 m into the north-bound lane of the east column.
  (``robotarium2``'s 13 signs on the road all stand at its edge, on 99 road tiles.)
- ``ETH_small_intersect`` (5 x 3 tiles, 13 road tiles, two 3-way intersections joined by a
  middle road, no objects but floor tags): the smallest map with intersections (``4way``,
  ``udem1``, ``TTIC_ripltown`` have 21-22 road tiles), near ``small_loop``'s 8 for 500k frames.

On both, the default task steps and renders from pixels (300-400 random steps, episodes ending
off the road or, on ``regress_4way_adam``, on an obstacle), 200 spawns each succeed, and with
``spawn.encounters=1`` every spawn on ``regress_4way_adam`` faces a barrier. Neither road is a
single loop, so their evaluations have no start directions.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from crllk.config import validate
from crllk.evaluation.report import aggregate
from crllk.experiments.runs import (
    THRESHOLDS,
    Outcome,
    RunSpec,
    Settings,
    deployed_forms,
    deployed_label,
    train_and_evaluate,
)
from crllk.experiments.seeds import SEED_OF_RUN, direction_cells, seed_cells
from crllk.experiments.tables import invocation, invocation_note, settings_dict, write_documents
from crllk.paths import SOURCE_ROOT
from crllk.training.compose import compose_config

REALMAPS_AGENT = "CRLLK-D"
REAL_MAPS_DIR = SOURCE_ROOT / "tests" / "data" / "real_maps" / "duckietown-world"
REALMAPS = {
    "regress_4way_adam": "objects in the driving lane: two barriers block a lane (one the whole "
                         "west-bound lane of the bottom row), a cone, two duckies and a "
                         "building's corner stand on the road; four 3-way and one 4-way "
                         "intersection, 21 road tiles",
    "ETH_small_intersect": "intersections: two 3-way intersections joined by a middle road, "
                           "13 road tiles, no objects",
}
"""The maps (stems of files in :data:`REAL_MAPS_DIR`) and what each puts to the agent."""


def map_file(name: str) -> str:
    """The path of a map file as the trainer gets it: relative to the working directory when
    it lies below it (so a run's ``config.yaml`` names it as the repository does), else
    absolute."""
    path = REAL_MAPS_DIR / f"{name}.yaml"
    try:
        return str(path.relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def realmaps_specs(settings: Settings, maps: Sequence[str] = tuple(REALMAPS)) -> list[RunSpec]:
    """CRLLK-D on every map file and seed."""
    return [RunSpec(REALMAPS_AGENT, name, seed, task_file=map_file(name))
            for name in maps for seed in settings.seeds]


def check_map_runs(specs: Sequence[RunSpec], settings: Settings) -> None:
    """Composes each map file's trainer configuration with the ``--set`` overrides.

    Raises:
        ConfigError: e.g. for a ``task.*`` override, which a map file does not take.
    """
    for path in dict.fromkeys(s.task_file for s in specs):
        validate(compose_config([f"agent={REALMAPS_AGENT}", f"task_file={path}",
                                 f"obs={settings.obs}", f"total_frames={settings.frames}",
                                 *settings.train_overrides]))


def realmaps(settings: Settings) -> list[Path]:
    """Trains what is missing, evaluates on the test seed, writes ``realmaps.json`` and
    ``realmaps.md`` into ``<results>/<obs>/``."""
    specs = realmaps_specs(settings)
    check_map_runs(specs, settings)
    outcome = train_and_evaluate(specs, settings)
    document = realmaps_document(outcome, settings)
    return write_documents(settings, "realmaps", document, realmaps_markdown(document))


def _entry(documents: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """:func:`aggregate` of a map's runs, with each run's terminations and collisions by
    object."""
    entry = aggregate(list(documents))
    entry["terminations"] = [dict(d.get("terminations", {})) for d in documents]
    entry["collisions_by_object"] = [dict(d.get("breakdown", {}).get("collisions_by_object", {}))
                                     for d in documents]
    return entry


def realmaps_document(outcome: Outcome, settings: Settings) -> dict[str, Any]:
    """Per map: its file, what it tests, and the runs' test evaluations (sampled policy, and
    under ``"mode"`` the deployed one where every seed's was evaluated)."""
    maps: dict[str, Any] = {}
    for name in dict.fromkeys(s.task_folder for s in outcome.documents):
        specs = [s for s in outcome.documents if s.task_folder == name]
        entry = {"file": specs[0].task_file, "about": REALMAPS.get(name, ""),
                 **_entry([outcome.documents[s] for s in specs])}
        if all(s in outcome.modes for s in specs):
            modes = [outcome.modes[s] for s in specs]
            entry["mode"] = {**_entry(modes), "deployed": deployed_forms(modes)}
        maps[name] = entry
    return {"title": f"Maps nobody tuned on: {REALMAPS_AGENT} ({settings.obs})",
            "thresholds": THRESHOLDS, "settings": settings_dict(settings),
            **invocation(outcome), "maps": maps}


def miss_lines(entry: Mapping[str, Any], thresholds: Mapping[str, float],
               policy: str) -> list[str]:
    """One line per run of ``entry`` that misses a constraint on its point estimate or its
    95 % upper bound: by how much, how its episodes ended, what it hit, per start direction."""
    intervals = entry.get("intervals", {})
    lines = []
    for index, run in enumerate(entry["runs"]):
        misses = []
        for c in entry["constraints"]:
            metric, bound = c["metric"], thresholds[c["name"]]
            value = entry[metric]["values"][index]
            unit = f" {c['unit']}" if c["unit"] == "dm" else ""
            high = intervals[metric][index][1] if metric in intervals else None
            if value > bound:
                misses.append(f"{metric} {value:.3f}{unit} over {bound:g} by "
                              f"{value - bound:.3f}" + ("" if high is None else
                                                        f" (95 % upper bound {high:.3f})"))
            elif high is not None and high > bound:
                misses.append(f"{metric} {value:.3f}{unit} holds, its 95 % upper bound "
                              f"{high:.3f} over {bound:g} by {high - bound:.3f}")
        if not misses:
            continue
        ended = sorted(entry["terminations"][index].items(), key=lambda item: -item[1])
        hits = entry["collisions_by_object"][index]
        text = (f"- seed {_seed(run)}, {policy}: {'; '.join(misses)}. Episodes ended: "
                + ", ".join(f"{reason} {count}" for reason, count in ended) + ". "
                + ("Objects hit (index, kind, position in m): " + ", ".join(
                    f"{name} ×{count}" for name, count in hits.items()) if hits
                   else "Objects hit: none"))
        directions = entry.get("by_direction", [])
        if index < len(directions) and directions[index]:
            text += ". " + "; ".join(
                f"started {direction}: {row['episodes']} episodes, " + ", ".join(
                    f"{c['metric']} {row[c['metric']]:.3f}" for c in entry["constraints"])
                for direction, row in directions[index].items())
        lines.append(text + ".")
    return lines


def _seed(run: str) -> int:
    match = SEED_OF_RUN.search(run)
    if match is None:
        raise ValueError(f"run directory {run!r} does not end in -seed<N>")
    return int(match.group(1))


def realmaps_markdown(document: Mapping[str, Any]) -> str:
    """The experiment's Markdown from its JSON document: per map a row per seed, then each
    run that misses a constraint and why."""
    thresholds, settings = document["thresholds"], document["settings"]
    lines = [f"# {document['title']}", "",
             f"{REALMAPS_AGENT} with its default configuration on Duckietown map files no "
             f"setting was tuned on; α1 = {thresholds['lane']} dm, α2 = "
             f"{thresholds['collision']} collisions per episode. Each cell: J_clane (dm) / "
             "J_coll / J_R (m) of one training run, with the 95 % intervals of the "
             "constraints' metrics (J_coll counts the episodes that end off the road or on "
             "an object); marks: both constraints hold on the point estimate, then at the "
             "95 % upper bound. Below each map, every run that misses: by how much, how its "
             "episodes ended and what they hit.", "",
             f"- Observation: `{settings['obs']}`; budget {settings['frames']:,} frames per run; "
             f"{settings['episodes']} test episodes per run from spawn seed "
             f"{settings['eval_seed']} (the test seed).",
             f"- Command: `{settings['command']}` ({invocation_note(document)}).",
             f"- Machine: {settings['machine']}.", ""]
    for name, entry in document["maps"].items():
        sampled = seed_cells(entry, thresholds)
        mode = seed_cells(entry["mode"], thresholds) if "mode" in entry else {}
        deployed = deployed_label([entry.get("mode")])
        lines += [f"## {name} (`{entry['file']}`)", "", f"{entry['about']}.", "",
                  f"| seed | sampled policy | {deployed} |", "| --- | --- | --- |"]
        lines += [f"| {seed} | {sampled[seed]} | {mode.get(seed, '—')} |"
                  for seed in sorted(sampled)]
        policies = [("sampled policy", entry)] + (
            [(deployed, entry["mode"])] if mode else [])
        for label, source in policies:
            if "by_direction" in source:
                cells = direction_cells(source, thresholds)
                lines += ["", f"By start direction ({label}):", "",
                          "| seed | intended | reverse |", "| --- | --- | --- |"]
                lines += [f"| {seed} | {cells.get((seed, 'intended'), '—')} | "
                          f"{cells.get((seed, 'reverse'), '—')} |"
                          for seed in sorted({seed for seed, _ in cells})]
        misses = [line for label, source in policies
                  for line in miss_lines(source, thresholds, label)]
        lines += ["", *(["Runs that miss:", "", *misses] if misses else
                        ["Every run holds both constraints, on the point estimate and at the "
                         "95 % upper bound."]), ""]
    return "\n".join(lines)


__all__ = ["REALMAPS", "REALMAPS_AGENT", "REAL_MAPS_DIR", "check_map_runs", "map_file",
           "miss_lines", "realmaps", "realmaps_document", "realmaps_markdown", "realmaps_specs"]
