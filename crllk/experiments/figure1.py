"""Figure 1's numbers in words: ``results/<obs>/figure1.md``, written beside the pictures.

Per lane threshold α1: every seed's test evaluation (the sampled policy and the deployed mode),
its final λ_lane, and the fixed-weight PPO-D pair of the sweep (``sweep.json``, same map and
observation) that travels farthest while holding J_clane ≤ α1 and J_coll ≤ α2 on every seed:
what a sweep would have had to find to match CRLLK-D's one run per threshold.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from crllk.training.runs import EXPECTED_DUTY

COLLISION_THRESHOLD = 0.02
"""α2 (collisions per episode) of every Figure 1 run; the sweep document states its own."""


def best_fixed_pair(fixed: list[Mapping[str, Any]], lane_threshold: float,
                    collision_threshold: float) -> Mapping[str, Any] | None:
    """The fixed-weight pair with the largest mean J_R whose every seed holds
    J_clane ≤ ``lane_threshold`` and J_coll ≤ ``collision_threshold``; None if none does."""
    holding = [e for e in fixed
               if max(e["J_clane"]["values"]) <= lane_threshold
               and max(e["J_coll"]["values"]) <= collision_threshold]
    return max(holding, key=lambda e: e["J_R"]["mean"], default=None)


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)


def _seed_cells(summaries: list[Mapping[str, Any]]) -> str:
    return "; ".join(f"{s['J_clane']:.3f} / {s['J_coll']:.3f} / {s['J_R']:.2f}"
                     for s in summaries) or "not evaluated"


def figure1_markdown(data: Mapping[str, Any], sweep: Mapping[str, Any] | None) -> str:
    """The Markdown of ``figure1.md`` from ``figure1.json``'s ``data`` and the ``sweep``
    document (None: no fixed-weight column)."""
    settings = data["settings"]
    fixed = (sweep or {}).get("maps", {}).get("small_loop", {}).get("fixed", [])
    collision = (sweep or {}).get("thresholds", {}).get("collision", COLLISION_THRESHOLD)
    lines = [
        f"# Figure 1: CRLLK-D on small_loop from {settings['obs']}, α1 against travel", "",
        f"Test evaluations ({settings['episodes']} episodes per run, the test seed), training "
        f"seeds {', '.join(map(str, settings['seeds']))}; each cell lists the seeds in order as "
        f"J_clane (dm) / J_coll (per episode) / J_R (m). α2 = {collision:g}. The fixed-weight "
        "column is the PPO-D pair of `sweep.json` that travels farthest while holding both "
        "constraints at that α1 on every seed.", "",
        f"- Command: `{settings['command']}`; budget {settings['frames']:,} frames per run.",
        f"- Machine: {settings['machine']}.", "",
        f"| α1 (dm) | sampled policy, per seed | {_deployed(data)}, per seed | final λ_lane "
        "| best fixed pair (λ_lane/λ_coll): J_clane / J_R |",
        "| --- | --- | --- | --- | --- |"]
    for threshold, entry in data["thresholds"].items():
        best = best_fixed_pair(fixed, float(threshold), collision) if fixed else None
        best_cell = ("none holds" if best is None else
                     f"{best['lane_weight']:g}/{best['collision_weight']:g}: "
                     f"{best['J_clane']['mean']:.3f} / {best['J_R']['mean']:.2f}")
        if not fixed:
            best_cell = "no sweep"
        lambdas = ", ".join(f"{v:.3f}" for v in entry["final_lambda_lane"])
        lines.append(f"| {threshold} | {_seed_cells(entry['evaluations'])} "
                     f"| {_seed_cells(entry.get('mode_evaluations', []))} | {lambdas} "
                     f"| {best_cell} |")
    lines += ["", *_summary(data, fixed, collision), ""]
    return "\n".join(lines)


def _summary(data: Mapping[str, Any], fixed: list[Mapping[str, Any]],
             collision: float) -> list[str]:
    """One sentence per threshold: does the sampled policy hold α1 on every seed, by how
    much does its mean J_R differ from the best fixed pair's, does the mode hold."""
    sentences = []
    for threshold, entry in data["thresholds"].items():
        alpha = float(threshold)
        sampled = entry["evaluations"]
        holds = all(s["J_clane"] <= alpha and s["J_coll"] <= collision for s in sampled)
        travel = _mean([s["J_R"] for s in sampled])
        text = (f"α1 = {threshold}: the sampled policy {'holds' if holds else 'misses'} both "
                f"constraints on every seed (J_clane {_mean([s['J_clane'] for s in sampled]):.3f}"
                f" dm, J_R {travel:.2f} m)")
        best = best_fixed_pair(fixed, alpha, collision) if fixed else None
        if best is not None:
            text += (f", {travel - best['J_R']['mean']:+.2f} m against the best fixed pair "
                     f"that holds ({best['lane_weight']:g}/{best['collision_weight']:g})")
        modes = entry.get("mode_evaluations", [])
        if modes:
            mode_holds = all(s["J_clane"] <= alpha and s["J_coll"] <= collision for s in modes)
            text += (f"; the {_deployed(data)} {'holds' if mode_holds else 'misses'} "
                     f"(J_clane {_mean([s['J_clane'] for s in modes]):.3f} dm)")
        sentences.append(f"- {text}.")
    return sentences


def _deployed(data: Mapping[str, Any]) -> str:
    """The deployed policies' name: ``deployed mode``, or ``deployed policy (expected
    duties)`` once their evaluations played those."""
    if any(EXPECTED_DUTY in entry.get("deployed", ()) for entry in data["thresholds"].values()):
        return "deployed policy (expected duties)"
    return "deployed mode"


__all__ = ["COLLISION_THRESHOLD", "best_fixed_pair", "figure1_markdown"]
