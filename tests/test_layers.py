"""The package's layers: each module imports only from its own layer or the ones below, and
no two modules import each other, directly or through others."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import crllk

PACKAGE = Path(crllk.__file__).parent

LAYERS = (
    ("crllk.errors", "crllk.files", "crllk.paths", "crllk.protocol", "crllk.settings", "crllk.cli",
     "crllk.images", "crllk.network", "crllk.yaml_files"),
    ("crllk.maps",),
    ("crllk.sim",),
    ("crllk.tasks",),
    ("crllk.envs", "crllk.gym"),
    ("crllk.rl", "crllk.config", "crllk.saved_config"),
    ("crllk.recording",),
    ("crllk.algos",),
    ("crllk.training",),
    ("crllk.evaluation",),
    ("crllk.analysis", "crllk.deployment"),
    ("crllk.train", "crllk.evaluate", "crllk.record", "crllk.experiments", "crllk.pictures",
     "crllk.screenshots", "crllk.demo", "crllk.bench", "crllk.export", "crllk.deploy",
     "crllk.convert", "crllk.peers"),
)
"""Bottom to top, in the order data flows: maps, MuJoCo, dm-control tasks, TorchRL
environments, learning (and a run's settings), recording, the learners, the trainer, evaluation
of runs, analysis, commands."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _layer(module: str) -> int:
    for level, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return level
    raise AssertionError(f"{module} belongs to no layer; add it to LAYERS")


def _imports(path: Path) -> set[str]:
    """The crllk modules ``path`` imports, at any depth of its code."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("crllk.")}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.startswith("crllk."):
                found.add(node.module)
            elif node.module == "crllk":  # from crllk import maps
                found |= {f"crllk.{a.name}" for a in node.names
                          if (PACKAGE / a.name).is_dir() or (PACKAGE / f"{a.name}.py").exists()}
    return found


MODULES = {_module_name(p): _imports(p) for p in sorted(PACKAGE.rglob("*.py"))
           if p.parent.name != "conf" and _module_name(p) != "crllk"}


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_upward_imports(module):
    level = _layer(module)
    upward = sorted(m for m in MODULES[module] if _layer(m) > level)
    assert not upward, f"{module} (layer {level}) imports from above: {upward}"


def test_no_import_cycles():
    graph = {m: {i for i in imports if i in MODULES} for m, imports in MODULES.items()}
    visiting, done, cycles = set(), set(), []

    def visit(module: str, trail: list[str]) -> None:
        if module in done:
            return
        if module in visiting:
            cycles.append([*trail[trail.index(module):], module])
            return
        visiting.add(module)
        for nxt in sorted(graph[module]):
            visit(nxt, [*trail, module])
        visiting.discard(module)
        done.add(module)

    for module in sorted(graph):
        visit(module, [])
    assert not cycles, " ; ".join(" -> ".join(c) for c in cycles)


def test_every_module_has_a_layer():
    for module in MODULES:
        _layer(module)
