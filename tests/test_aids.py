"""The training aids' ablation (``python -m crllk.experiments aids``) and the machinery it shares
with the teacher's: which runs, which overrides, the document and its Markdown."""

from __future__ import annotations

import importlib
import json
from pathlib import Path
from typing import Any

import pytest

from crllk.config import validate
from crllk.experiments import EXPERIMENTS
from crllk.experiments.aids import AIDS, aids, aids_markdown, aids_specs, buys_lines
from crllk.experiments.runs import THRESHOLDS, Outcome, RunSpec, Settings, sweep_commands
from crllk.experiments.teacher import TEACHER, TEACHER_VARIANTS, teacher_markdown, teacher_specs
from crllk.training.compose import compose_config

REPO = Path(__file__).resolve().parents[1]
CONSTRAINTS = [{"name": "lane", "metric": "J_clane", "unit": "dm"},
               {"name": "collision", "metric": "J_coll", "unit": "per episode"}]


def test_aids_runs_the_default_and_each_variant_on_its_maps():
    """Default and pixel critics on both maps, no encounter spawns on obstacle_loop alone, two
    seeds each: ten runs, four of them the tables' default runs, six new."""
    specs = aids_specs(Settings())
    assert EXPERIMENTS["aids"] is aids
    names = {(s.task, s.directory(Path("r")).name) for s in specs}
    assert len(specs) == len(names) == 10
    assert names == {(task, f"CRLLK-D{tag}-a0.5-seed{seed}") for seed in (0, 1)
                     for task, tag in [("obstacle_loop", ""), ("small_loop", ""),
                                       ("obstacle_loop", "-noencounters"),
                                       ("obstacle_loop", "-pixelcritics"),
                                       ("small_loop", "-pixelcritics")]}
    extras = {(s.task, s.tag): s.extra for s in specs}
    assert extras == {("obstacle_loop", ""): (), ("small_loop", ""): (),
                      ("obstacle_loop", "-noencounters"): ("encounters=0",),
                      ("obstacle_loop", "-pixelcritics"): ("model.critic_input=observation",),
                      ("small_loop", "-pixelcritics"): ("model.critic_input=observation",)}
    assert {s.seed for s in aids_specs(Settings(seeds=(3,)))} == {3}
    # from state the critics read the state anyway: no pixel-critics runs
    assert {s.tag for s in aids_specs(Settings(obs="state"))} == {"", "-noencounters"}
    commands = sweep_commands(specs, Settings())
    assert len(commands) == 3  # one sweep per set of overrides, both maps in one
    assert sum("encounters=0" in c for c in commands) == 1
    assert not any("encounter_curve_weight" in c for c in commands)


def test_teacher_runs_are_the_default_s_and_two_variants_on_each_map():
    """On both maps the tables' default runs, then the annealed and teacherless variants: the
    ablation runs the trainer's configuration, the same on every map."""
    specs = teacher_specs(Settings())
    assert len(specs) == 12
    assert specs[:3] == [RunSpec("CRLLK-D", "obstacle_loop", 0),
                         RunSpec("CRLLK-D", "obstacle_loop", 1),
                         RunSpec("CRLLK-D", "obstacle_loop", 0, tag="-teacher0",
                                 extra=("teacher.final=0", "teacher.frames=400000"))]
    assert RunSpec("CRLLK-D", "small_loop", 0) in specs
    assert not any("encounter_curve_weight" in o for s in specs for o in s.extra)
    assert list(TEACHER_VARIANTS) == ["floor 0.3 (default)", "annealed to 0 by 400k frames",
                                      "no teacher"]


@pytest.mark.parametrize(("ablation", "name"),
                         [(a, n) for a in (AIDS, TEACHER) for n in a.variants])
def test_every_variant_s_overrides_compose(ablation, name):
    """Each variant's overrides compose with the trainer's configuration on its maps, from
    pixels, and set what they say."""
    variant = ablation.variants[name]
    for task in (t for t in ablation.tasks if variant.applies(t, "pixels")):
        config = validate(compose_config(["agent=CRLLK-D", f"task={task}", "obs=pixels",
                                          "seed=0", *variant.overrides]))
        expected = {"": (0.5, "state", 1.0), "-noencounters": (0.0, "state", 1.0),
                    "-pixelcritics": (0.5, "observation", 1.0),
                    "-noteacher": (0.5, "state", 0.0), "-teacher0": (0.5, "state", 1.0)}
        assert (config.encounters, config.model.critic_input,
                config.teacher.coeff) == expected[variant.tag]


def _entry(seeds: dict[int, tuple[float, float, float]], tag: str = "",
           directions: bool = False) -> dict[str, Any]:
    """An aggregate entry (:func:`crllk.evaluation.report.aggregate`) of hand-made numbers:
    per seed J_clane, J_coll, J_R; intervals of ±0.01 around each constraint's metric."""
    runs = [f"runs/obstacle_loop/CRLLK-D{tag}-a0.5-seed{seed}" for seed in seeds]
    values = list(seeds.values())
    entry: dict[str, Any] = {"runs": runs, "constraints": CONSTRAINTS}
    for k, metric in enumerate(("J_clane", "J_coll", "J_R")):
        column = [v[k] for v in values]
        entry[metric] = {"mean": sum(column) / len(column), "std": 0.0, "values": column}
    entry["satisfied"] = [v[0] <= THRESHOLDS["lane"] and v[1] <= THRESHOLDS["collision"]
                          for v in values]
    entry["intervals"] = {m: [[max(v[k] - 0.01, 0.0), v[k] + 0.01] for v in values]
                          for k, m in enumerate(("J_clane", "J_coll"))}
    if directions:
        entry["by_direction"] = [
            {d: {"episodes": 200, "J_clane": v[0], "J_clane_interval": [v[0] - 0.01, v[0] + 0.01],
                 "J_coll": v[1], "J_coll_interval": [v[1] - 0.01, v[1] + 0.01]}
             for d in ("intended", "reverse")} for v in values]
    return entry


def _document() -> dict[str, Any]:
    default = _entry({0: (0.3, 0.01, 2.7), 1: (0.35, 0.005, 2.6)}, directions=True)
    default["mode"] = _entry({0: (0.4, 0.0, 2.65), 1: (0.45, 0.03, 2.6)})
    without = _entry({0: (0.25, 0.05, 2.5), 1: (0.3, 0.04, 2.4)}, "-noencounters",
                     directions=True)
    without["mode"] = _entry({0: (0.2, 0.1, 2.4), 1: (0.6, 0.0, 2.7)}, "-noencounters")
    variants = {name: {"tag": v.tag, "overrides": list(v.overrides), "aid": v.aid,
                       "tasks": [t for t in AIDS.tasks if v.applies(t, "pixels")]}
                for name, v in AIDS.variants.items()}
    return {"title": "The training aids measured: CRLLK-D (pixels)", "thresholds": THRESHOLDS,
            "settings": {"obs": "pixels", "frames": 500_000, "episodes": 400,
                         "eval_seed": 31415926, "command": "python -m crllk.experiments aids",
                         "machine": "a test"},
            "wall_s": 60.0, "runs_total": 4, "runs_trained": 2, "evaluations_made": 8,
            "baseline": "default", "variants": variants,
            "maps": {"obstacle_loop": {"default": default, "no encounter spawns": without}}}


def test_what_an_aid_buys_is_its_numbers():
    """The default collides 0.01 per episode (seed 0) and 0.005 (seed 1), without encounter
    spawns 0.05 and 0.04: the line says so, per seed, and counts the seeds where both
    constraints hold (the default's upper bounds, 0.02 and 0.015, hold; its deployed seed 1
    collides 0.03 per episode, above α2 = 0.02)."""
    (line,) = buys_lines(_document())
    sampled, deployed = line.split(". Deployed policy (mode): ")
    assert sampled == (
        "- **encounter spawns** on obstacle_loop (default → no encounter spawns). Sampled "
        "policy: J_clane 0.300 → 0.250 (seed 0), 0.350 → 0.300 (seed 1); "
        "J_coll 0.01 → 0.05 (seed 0), 0.01 → 0.04 (seed 1); "
        "J_R 2.70 → 2.50 (seed 0), 2.60 → 2.40 (seed 1); "
        "constraints hold in 2 → 0 of 2 seeds (at the upper bound 2 → 0)")
    assert deployed == ("J_clane 0.400 → 0.200 (seed 0), 0.450 → 0.600 (seed 1); "
                        "J_coll 0.00 → 0.10 (seed 0), 0.03 → 0.00 (seed 1); "
                        "J_R 2.65 → 2.40 (seed 0), 2.60 → 2.70 (seed 1); "
                        "constraints hold in 1 → 0 of 2 seeds (at the upper bound 1 → 0).")


def test_aids_markdown_has_every_seed_the_directions_and_the_variants():
    markdown = aids_markdown(_document())
    lines = markdown.splitlines()
    assert lines[0] == "# The training aids measured: CRLLK-D (pixels)"
    assert ("- Variants: default (the trainer's configuration; obstacle_loop, small_loop); "
            "no encounter spawns (`-noencounters`: `encounters=0`; obstacle_loop); pixel "
            "critics (`-pixelcritics`: `model.critic_input=observation`; obstacle_loop, "
            "small_loop).") in lines
    assert lines.index("## What each aid buys") < lines.index("## obstacle_loop")
    assert "| variant | seed | sampled policy | deployed policy (mode) |" in lines
    assert ("| default | 0 | 0.300 (0.29–0.31) / 0.01 (0.00–0.02) / 2.70 ✓ ✓ | "
            "0.400 (0.39–0.41) / 0.00 (0.00–0.01) / 2.65 ✓ ✓ |") in lines
    assert ("| no encounter spawns | 1 | 0.300 (0.29–0.31) / 0.04 (0.03–0.05) / 2.40 ✗ ✗ | "
            "0.600 (0.59–0.61) / 0.00 (0.00–0.01) / 2.70 ✗ ✗ |") in lines
    assert ("| no encounter spawns | 0 | 200 episodes: 0.250 (0.24–0.26) / 0.05 (0.04–0.06) "
            "✗ ✗ | 200 episodes: 0.250 (0.24–0.26) / 0.05 (0.04–0.06) ✗ ✗ |") in lines
    assert "Command: `python -m crllk.experiments aids` (1.0 min wall" in markdown


def test_aids_writes_its_documents(tmp_path, monkeypatch):
    """``aids`` from hand-made evaluations (no training): the JSON describes the variants and
    the Markdown is rebuilt from it; the teacher's document has no such entries."""
    def evaluation(spec: RunSpec) -> dict[str, Any]:
        collisions = 0.05 if spec.tag else 0.01
        rows = [{"cost_lane": 0.3, "cost_collision": float(k < 100 * collisions),
                 "direction": ("intended", "reverse")[k % 2]} for k in range(100)]
        return {"source": {"run_dir": str(spec.directory(tmp_path))}, "constraints": CONSTRAINTS,
                "summary": {"J_R": 2.5, "J_clane": 0.3, "J_coll": collisions,
                            "episode_length": 500, "satisfied": not spec.tag},
                "episodes": rows}

    def fake(specs: list[RunSpec], settings: Settings) -> Outcome:
        documents = {s: evaluation(s) for s in specs}
        return Outcome(documents, 1.0, dict(documents), trained=6, evaluated=12)

    module = importlib.import_module("crllk.experiments.aids")  # the package's `aids` is the
    monkeypatch.setattr(module, "train_and_evaluate", fake)  # experiment, not the module
    settings = Settings(results=tmp_path / "results", command="python -m crllk.experiments aids")
    json_path, md_path = aids(settings)
    document = json.loads(json_path.read_text())
    assert md_path.read_text() == aids_markdown(document)
    assert document["baseline"] == "default"
    assert document["variants"]["no encounter spawns"]["tasks"] == ["obstacle_loop"]
    assert {task: list(entries) for task, entries in document["maps"].items()} == {
        "obstacle_loop": ["default", "no encounter spawns", "pixel critics"],
        "small_loop": ["default", "pixel critics"]}
    assert "J_coll 0.01 → 0.05 (seed 0), 0.01 → 0.05 (seed 1)" in md_path.read_text()
    teacher_document = TEACHER.document(fake(TEACHER.specs(settings), settings), settings)
    assert "baseline" not in teacher_document and "variants" not in teacher_document
    assert list(teacher_document["maps"]["small_loop"]) == list(TEACHER_VARIANTS)


@pytest.mark.parametrize(("name", "writer"), [("teacher", teacher_markdown),
                                              ("aids", aids_markdown)])
def test_the_kept_ablation_markdown_is_rebuilt_unchanged(name, writer):
    path = REPO / "results" / "pixels" / f"{name}.json"
    if not path.is_file():
        pytest.skip(f"no {name}.json kept")
    assert writer(json.loads(path.read_text())) == path.with_suffix(".md").read_text()
