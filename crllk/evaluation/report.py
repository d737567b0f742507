"""An evaluation as a document: the paper's metrics, breakdowns, one row per episode; and mean ±
std across runs."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from crllk.envs.episodes import summarise
from crllk.evaluation import community
from crllk.evaluation.community import at_or_none
from crllk.evaluation.intervals import metric_interval
from crllk.rl.rollout import EvaluationResult
from crllk.tasks.actions import DISCRETE_NAMES
from crllk.tasks.constraints import cost_key

CONTINUOUS_BINS = np.linspace(-1.0, 1.0, 11)
"""Edges of the continuous action histogram (velocity and steering lie in [-1, 1])."""


PAPER_CONSTRAINTS = ({"name": "lane", "metric": "J_clane", "unit": "dm"},
                     {"name": "collision", "metric": "J_coll", "unit": "per episode"})
"""What an ``eval.json`` without a ``constraints`` entry (an older one) constrains."""


def constraint_entries(document: dict[str, Any]) -> list[dict[str, Any]]:
    """The constraints of an evaluation document: name, metric, unit, aggregate, threshold."""
    return list(document.get("constraints") or PAPER_CONSTRAINTS)


_OLDER_ROW_KEYS = {"lane": "lane_cost", "collision": "collisions"}
"""Where an older ``eval.json`` row kept the paper's two costs."""


def episode_cost(row: dict[str, Any], name: str) -> float:
    """Constraint ``name``'s value in one episode row of an ``eval.json`` (``cost_<name>``)."""
    key = cost_key(name)
    return float(row[key] if key in row else row[_OLDER_ROW_KEYS[name]])


def constraint_intervals(document: dict[str, Any]) -> dict[str, list[float]]:
    """``{metric: [low, high]}``, the 95 % confidence interval of each constraint's metric
    from the document's episode rows (:func:`crllk.evaluation.intervals.metric_interval`;
    empty where it has fewer than two episodes)."""
    rows = document.get("episodes") or []
    if len(rows) < 2:
        return {}
    return {c["metric"]: list(metric_interval([episode_cost(row, c["name"]) for row in rows]))
            for c in constraint_entries(document)}


DIRECTIONS = ("intended", "reverse")
"""The start directions of a loop whose obstacles block one of them (an episode row's
``direction``)."""


def direction_results(document: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Per start direction (where the episode rows record one): how many episodes, each
    constraint's metric and its 95 % interval (``"<metric>_interval"``), from the rows."""
    rows = document.get("episodes") or []
    out = {}
    for direction in DIRECTIONS:
        chosen = [row for row in rows if row.get("direction") == direction]
        if len(chosen) < 2:
            continue
        entry: dict[str, Any] = {"episodes": len(chosen)}
        for c in constraint_entries(document):
            values = [episode_cost(row, c["name"]) for row in chosen]
            entry[c["metric"]] = float(np.mean(values))
            entry[f"{c['metric']}_interval"] = list(metric_interval(values))
        out[direction] = entry
    return out


def metrics(document: dict[str, Any]) -> list[str]:
    """The metrics of a document's summary: J_R, each constraint's, the episode length."""
    return ["J_R", *(c["metric"] for c in constraint_entries(document)), "episode_length"]


def action_histogram(actions: Sequence[np.ndarray], action: str) -> dict[str, Any]:
    """Discrete: the fraction of steps per action; continuous (and duty): counts per bin of
    each action component over :data:`CONTINUOUS_BINS`."""
    flat = np.concatenate([np.asarray(a).reshape(len(a), -1) for a in actions])
    if action == "discrete":
        counts = np.bincount(flat[:, 0].astype(np.int64), minlength=len(DISCRETE_NAMES))
        return {name: float(c / counts.sum()) for name, c in zip(DISCRETE_NAMES, counts,
                                                                   strict=True)}
    names = ("left", "right") if action == "duty" else ("velocity", "steering")
    return {"bin_edges": CONTINUOUS_BINS.tolist(),
            **{name: np.histogram(np.clip(flat[:, k], -1, 1), CONTINUOUS_BINS)[0].tolist()
               for k, name in enumerate(names)},
            **{f"{name}_mean": float(flat[:, k].mean()) for k, name in enumerate(names)}}


def episode_rows(result: EvaluationResult, action: str) -> list[dict[str, Any]]:
    rows = []
    for k, (stats, termination, actions) in enumerate(
            zip(result.episodes, result.terminations, result.actions, strict=True)):
        reason = termination or ("time_limit" if stats.truncated else None)
        row = {"episode": k, **stats.as_row(), "termination": reason,
               "direction": at_or_none(result.directions, k),
               "hit_object": at_or_none(result.hit_objects, k),
               "hit_mover": at_or_none(result.hit_movers, k)}
        if action == "discrete":
            counts = np.bincount(np.asarray(actions).reshape(-1).astype(np.int64),
                                 minlength=len(DISCRETE_NAMES))
            row["actions"] = dict(zip(DISCRETE_NAMES, counts.tolist(), strict=True))
        rows.append(row)
    return rows


def breakdown(result: EvaluationResult, objects: Sequence[Any] = ()) -> dict[str, Any]:
    """The metrics per start direction of the loop, and how many episodes ended on each
    obstacle (``objects``: the map's, to name them by kind and position) and on each moving
    agent (by index: vehicles, then pedestrians)."""
    by_direction = {}
    for direction in ("intended", "reverse"):
        chosen = [e for e, d in zip(result.episodes, result.directions, strict=True)
                  if d == direction]
        if chosen:
            by_direction[direction] = summarise(chosen, result.constraints).as_row()
    hits: dict[str, int] = {}
    for index in result.hit_objects:
        if index is not None:
            obj = objects[index] if index < len(objects) else None
            name = f"{index}" if obj is None else f"{index} {obj.kind} ({obj.x:.2f}, {obj.y:.2f})"
            hits[name] = hits.get(name, 0) + 1
    movers: dict[str, int] = {}
    for index in result.hit_movers:
        if index is not None:
            movers[str(index)] = movers.get(str(index), 0) + 1
    return {"by_direction": by_direction, "collisions_by_object": dict(sorted(hits.items())),
            "collisions_by_mover": dict(sorted(movers.items()))}


def result_document(result: EvaluationResult, action: str, *, thresholds: dict[str, float],
                    settings: dict[str, Any], source: dict[str, Any],
                    objects: Sequence[Any] = (),
                    scales: community.Scales | None = None) -> dict[str, Any]:
    """The ``eval.json`` content of one evaluation (``objects``: the map's, named in the
    breakdown of collisions); with ``scales``, the community's metrics too, per episode and
    under ``"community"`` (:mod:`crllk.evaluation.community`)."""
    s = result.summary
    rows = episode_rows(result, action)
    if scales is not None:
        for row, extra in zip(rows, community.episode_metrics(result, scales, objects),
                              strict=True):
            row.update(extra)
    summary = {"J_R": s.J_R, **s.J, "episode_length": s.length,
               "satisfied": all(s.J[c.metric] <= thresholds[c.name]
                                for c in result.constraints)}
    constraints = [{"name": c.name, "metric": c.metric, "unit": c.unit,
                    "aggregate": c.aggregate, "threshold": thresholds[c.name]}
                   for c in result.constraints]
    document = {"source": source, "evaluation": settings, "thresholds": thresholds,
                "constraints": constraints,
                "summary": summary, "action_histogram": action_histogram(result.actions, action),
                "terminations": dict(Counter(row["termination"] for row in rows)),
                "breakdown": breakdown(result, objects)}
    if scales is not None:
        document["community"] = community.summary(rows)
    return {**document, "episodes": rows}


def aggregate(documents: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean and standard deviation (population, ddof 0) across runs of each metric, with
    the per-run values, and under ``"intervals"`` each run's 95 % confidence interval of each
    constraint's metric (where every run kept its episodes)."""
    out: dict[str, Any] = {"runs": [d["source"].get("run_dir") for d in documents],
                           "constraints": constraint_entries(documents[0])}
    for metric in metrics(documents[0]):
        values = [float(d["summary"][metric]) for d in documents]
        out[metric] = {"mean": float(np.mean(values)), "std": float(np.std(values)),
                       "values": values}
    out["satisfied"] = [bool(d["summary"]["satisfied"]) for d in documents]
    intervals = [constraint_intervals(d) for d in documents]
    if all(intervals):
        out["intervals"] = {c["metric"]: [i[c["metric"]] for i in intervals]
                            for c in out["constraints"]}
    directions = [direction_results(d) for d in documents]
    if any(directions):
        out["by_direction"] = directions
    return out


def format_summary(document: dict[str, Any]) -> str:
    s, src = document["summary"], document["source"]
    name = src.get("run_dir") or f"{src['algo']} on {src['task']}"
    constraints = constraint_entries(document)
    verdict = "every constraint holds" if s["satisfied"] else "constraints violated"
    text = (f"{name}: {document['evaluation']['episodes']} episodes: J_R {s['J_R']:.2f} m, "
            f"{_metrics_text(s, constraints, constraint_intervals(document))}, "
            f"length {s['episode_length']:.0f}: {verdict}")
    split = document.get("breakdown", {})
    for direction, row in split.get("by_direction", {}).items():
        text += (f"\n  started {direction}: {row['episodes']} episodes, "
                 f"{_metrics_text(row, constraints)}")
    if split.get("collisions_by_object"):
        text += "\n  ended on: " + ", ".join(f"{obstacle} ×{count}" for obstacle, count
                                            in split["collisions_by_object"].items())
    if document.get("community"):
        text += "\n  " + community.format_summary(document["community"])
    return text


def format_aggregate(result: dict[str, Any]) -> str:
    def show(metric: str, digits: int) -> str:
        return f"{result[metric]['mean']:.{digits}f} ± {result[metric]['std']:.{digits}f}"

    metrics = ", ".join(f"{c['metric']} {show(c['metric'], 3)} {c['unit']}"
                        for c in result["constraints"])
    return f"{len(result['runs'])} runs: J_R {show('J_R', 2)} m, {metrics}"


def _metrics_text(values: dict[str, Any], constraints: Sequence[dict[str, Any]],
                  intervals: dict[str, list[float]] | None = None) -> str:
    """``J_clane 0.399 dm, ...``; with ``intervals``, each followed by its 95 % interval."""
    def interval(metric: str) -> str:
        if not intervals or metric not in intervals:
            return ""
        low, high = intervals[metric]
        return f" (95 % interval {low:.3f}–{high:.3f})"

    return ", ".join(f"{c['metric']} {values[c['metric']]:.3f} {c['unit']}{interval(c['metric'])}"
                     for c in constraints)
