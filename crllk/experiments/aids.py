"""``python -m crllk.experiments aids``: what the default agent's training aids buy. CRLLK-D from
the default configuration beside variants that each go without one aid, on the maps the aid
concerns, every seed judged on the test seed (sampled policy and deployed policy, each start
direction apart):

- encounter spawns (``encounters=0.5``: half the training episodes start 0.3–1.2 m before an
  obstacle blocking their lane), without them (``encounters=0``) on obstacle_loop, the map
  with such obstacles;
- asymmetric critics (from pixels the critics read the privileged lane state), replaced by
  pixel critics (``model.critic_input=observation``) on obstacle_loop and small_loop.

The ablation machinery (:class:`Variant`, :class:`Ablation`, the JSON document and its
Markdown) is shared with :mod:`crllk.experiments.teacher`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from crllk.evaluation.report import aggregate
from crllk.experiments.runs import (
    THRESHOLDS,
    Outcome,
    RunSpec,
    Settings,
    deployed_label,
    mode_aggregate,
    train_and_evaluate,
)
from crllk.experiments.seeds import PER_SEED_METRICS, SEED_OF_RUN, direction_cells, seed_cells
from crllk.experiments.tables import invocation, invocation_note, settings_dict, write_documents


@dataclass(frozen=True)
class Variant:
    """One configuration of CRLLK-D in an ablation."""

    name: str
    tag: str = ""
    """Added to its runs' directory names (``""``: the default configuration's own runs)."""
    overrides: tuple[str, ...] = ()
    """Trainer overrides."""
    tasks: tuple[str, ...] | None = None
    """The maps it applies to (None: every map of the ablation)."""
    obs: str | None = None
    """The observation it applies to (None: either)."""
    aid: str = ""
    """The training aid it goes without, as the "what it buys" lines name it."""

    def applies(self, task: str, obs: str) -> bool:
        return (self.tasks is None or task in self.tasks) and self.obs in (None, obs)


def variants(*items: Variant) -> dict[str, Variant]:
    """The variants by name, in order."""
    return {variant.name: variant for variant in items}


@dataclass(frozen=True)
class Ablation:
    """An experiment of CRLLK-D variants: its runs, and ``<results>/<name>.{json,md}``."""

    name: str
    title: str
    """The documents' title, ``{obs}`` replaced by the observation."""
    variants: Mapping[str, Variant]
    tasks: tuple[str, ...]
    label: str = "variant"
    """The first column of the Markdown tables."""
    baseline: str | None = None
    """The variant the others are compared with, one "what it buys" line each (None: none)."""

    def specs(self, settings: Settings) -> list[RunSpec]:
        """CRLLK-D with each variant, on every map it applies to, and every seed."""
        specs = []
        for task in self.tasks:
            for v in self.variants.values():
                if v.applies(task, settings.obs):
                    specs += [RunSpec("CRLLK-D", task, seed, tag=v.tag, extra=v.overrides)
                              for seed in settings.seeds]
        return specs

    def run(self, settings: Settings) -> list[Path]:
        """Trains what is missing, evaluates on the test seed, writes the documents."""
        outcome = train_and_evaluate(self.specs(settings), settings)
        document = self.document(outcome, settings)
        return write_documents(settings, self.name, document,
                               ablation_markdown(document, self.label))

    def document(self, outcome: Outcome, settings: Settings) -> dict[str, Any]:
        """Per map and variant: the aggregate across seeds of the sampled policy and of the
        mode (with each run's intervals and start directions); with a baseline, the variants
        described too."""
        maps: dict[str, Any] = {}
        for task in dict.fromkeys(s.task for s in outcome.documents):
            entries = {}
            for name, variant in self.variants.items():
                specs = [s for s in outcome.documents
                         if s.task == task and s.tag == variant.tag]
                if not specs:
                    continue
                entry = aggregate([outcome.documents[s] for s in specs])
                if all(s in outcome.modes for s in specs):
                    entry["mode"] = mode_aggregate([outcome.modes[s] for s in specs])
                entries[name] = entry
            maps[task] = entries
        described: dict[str, Any] = {}
        if self.baseline is not None:
            described = {"baseline": self.baseline, "variants": {
                name: {"tag": v.tag, "overrides": list(v.overrides), "aid": v.aid,
                       "tasks": [t for t in self.tasks if v.applies(t, settings.obs)]}
                for name, v in self.variants.items()}}
        return {"title": self.title.format(obs=settings.obs), "thresholds": THRESHOLDS,
                "settings": settings_dict(settings), **invocation(outcome), **described,
                "maps": maps}


def ablation_markdown(document: Mapping[str, Any], label: str = "variant") -> str:
    """An ablation's Markdown from its JSON document: per map a row per variant and seed,
    then the start directions; first, where the document has a baseline, the variants and
    what each aid buys."""
    thresholds, settings = document["thresholds"], document["settings"]
    lines = [f"# {document['title']}", "",
             f"α1 = {thresholds['lane']} dm, α2 = {thresholds['collision']}. Each cell: J_clane "
             "(dm) / J_coll / J_R (m) of one training run, with the 95 % intervals of the "
             "constraints' metrics; marks: both constraints hold on the point estimate, then "
             "at the 95 % upper bound.", "",
             f"- Observation: `{settings['obs']}`; budget {settings['frames']:,} frames per run; "
             f"{settings['episodes']} test episodes per run from spawn seed "
             f"{settings['eval_seed']} (the test seed).",
             f"- Command: `{settings['command']}` ({invocation_note(document)}).",
             f"- Machine: {settings['machine']}."]
    if "variants" in document:
        lines.append("- Variants: " + "; ".join(
            f"{name} (" + (f"`{v['tag']}`: " + ", ".join(f"`{o}`" for o in v["overrides"])
                           if v["tag"] else "the trainer's configuration")
            + f"; {', '.join(v['tasks']) or 'no map'})"
            for name, v in document["variants"].items()) + ".")
    lines.append("")
    modes = [entry.get("mode") for entries in document["maps"].values()
             for entry in entries.values()]
    if "baseline" in document:
        lines += ["## What each aid buys", "",
                  f"{document['baseline']} → the variant without the aid, per training seed: "
                  f"the sampled policy, then the {deployed_label(modes)}, and in how many seeds "
                  "both "
                  "constraints hold, on the point estimate and at the 95 % upper bound.", "",
                  *buys_lines(document), ""]
    for task, entries in document["maps"].items():
        deployed = deployed_label(modes)
        lines += [f"## {task}", "", f"| {label} | seed | sampled policy | {deployed} |",
                  "| --- | --- | --- | --- |"]
        for name, entry in entries.items():
            sampled = seed_cells(entry, thresholds)
            mode = seed_cells(entry["mode"], thresholds) if "mode" in entry else {}
            for seed in sorted(sampled):
                lines.append(f"| {name} | {seed} | {sampled[seed]} | {mode.get(seed, '—')} |")
        directions = [(name, direction_cells(entry, thresholds))
                      for name, entry in entries.items() if "by_direction" in entry]
        if directions:
            lines += ["", "By start direction (sampled policy):", "",
                      f"| {label} | seed | intended | reverse |", "| --- | --- | --- | --- |"]
            for name, cells in directions:
                for seed in sorted({seed for seed, _ in cells}):
                    lines.append(f"| {name} | {seed} | {cells.get((seed, 'intended'), '—')} | "
                                 f"{cells.get((seed, 'reverse'), '—')} |")
        lines.append("")
    return "\n".join(lines)


def buys_lines(document: Mapping[str, Any]) -> list[str]:
    """One line per variant and map: the baseline's numbers beside the variant's, per seed."""
    baseline, thresholds, lines = document["baseline"], document["thresholds"], []
    for task, entries in document["maps"].items():
        default = entries.get(baseline)
        if default is None:
            continue
        for name, entry in entries.items():
            if name == baseline:
                continue
            aid = document["variants"].get(name, {}).get("aid") or name
            pairs = (("Sampled policy", default, entry),
                     (deployed_label([default.get("mode"), entry.get("mode")]).capitalize(),
                      default.get("mode"), entry.get("mode")))
            parts = [f"{policy}: {_compare(a, b, thresholds)}" for policy, a, b in pairs
                     if a is not None and b is not None]
            lines.append(f"- **{aid}** on {task} ({baseline} → {name}). " + ". ".join(parts)
                         + ".")
    return lines


def _compare(with_aid: Mapping[str, Any], without: Mapping[str, Any],
             thresholds: Mapping[str, float]) -> str:
    """``J_clane 0.300 → 0.400 (seed 0), ...`` for each metric, then how many seeds hold."""
    seeds = sorted(set(_by_seed(with_aid)) & set(_by_seed(without)))
    text = []
    for metric, digits in PER_SEED_METRICS:
        a, b = _values(with_aid, metric), _values(without, metric)
        text.append(f"{metric} " + ", ".join(
            f"{a[s]:.{digits}f} → {b[s]:.{digits}f} (seed {s})" for s in seeds))
    held = [_holds(e, thresholds) for e in (with_aid, without)]
    point = [sum(h[s][0] for s in seeds) for h in held]
    upper = [sum(h[s][1] for s in seeds) for h in held]
    return ("; ".join(text) + f"; constraints hold in {point[0]} → {point[1]} of {len(seeds)} "
            f"seeds (at the upper bound {upper[0]} → {upper[1]})")


def _by_seed(entry: Mapping[str, Any]) -> dict[int, int]:
    """``{training seed: index}`` of an aggregate entry's runs."""
    out = {}
    for index, run in enumerate(entry["runs"]):
        match = SEED_OF_RUN.search(run)
        if match is None:
            raise ValueError(f"run directory {run!r} does not end in -seed<N>")
        out[int(match.group(1))] = index
    return out


def _values(entry: Mapping[str, Any], metric: str) -> dict[int, float]:
    return {seed: entry[metric]["values"][i] for seed, i in _by_seed(entry).items()}


def _holds(entry: Mapping[str, Any], thresholds: Mapping[str, float],
           ) -> dict[int, tuple[bool, bool]]:
    """Per seed: both constraints hold on the point estimate, and at the 95 % upper bound
    (False where the entry has no intervals)."""
    intervals = entry.get("intervals")
    return {seed: (bool(entry["satisfied"][i]), intervals is not None and all(
        intervals[c["metric"]][i][1] <= thresholds[c["name"]] for c in entry["constraints"]))
        for seed, i in _by_seed(entry).items()}


AIDS_TASKS = ("obstacle_loop", "small_loop")
"""The maps of the aids' ablation: the one with obstacles in a lane, and Table 1's map."""
AIDS = Ablation(
    "aids", "The training aids measured: CRLLK-D ({obs})", variants(
        Variant("default"),
        Variant("no encounter spawns", "-noencounters", ("encounters=0",), ("obstacle_loop",),
                aid="encounter spawns"),
        Variant("pixel critics", "-pixelcritics", ("model.critic_input=observation",),
                obs="pixels", aid="asymmetric (state) critics")),
    AIDS_TASKS, baseline="default")
"""The default (the trainer's configuration, its runs those of the tables), without encounter spawns
where there are obstacles to meet, and with critics that read the camera like the actor (from
state the critics read the state anyway: no such variant)."""


def aids_specs(settings: Settings) -> list[RunSpec]:
    """The aids ablation's runs."""
    return AIDS.specs(settings)


def aids(settings: Settings) -> list[Path]:
    """Trains what is missing, evaluates on the test seed, writes ``aids.json`` and
    ``aids.md`` into ``<results>/<obs>/``."""
    return AIDS.run(settings)


def aids_markdown(document: Mapping[str, Any]) -> str:
    """``aids.md`` from ``aids.json``."""
    return ablation_markdown(document, "variant")


__all__ = ["AIDS", "AIDS_TASKS", "Ablation", "Variant", "ablation_markdown", "aids",
           "aids_markdown", "aids_specs", "buys_lines", "variants"]
