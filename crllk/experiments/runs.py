"""The runs of an experiment: what each one is, training and evaluating them as processes,
``--jobs`` at a time, and reusing the finished ones."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from crllk.evaluation.report import PAPER_CONSTRAINTS
from crllk.training.config import EVALUATION_SEED, algo_thresholds
from crllk.training.runs import CHECKPOINT_FILE, EVAL_FILE, read_eval_json

SOURCE = "experiments"
"""How errors name where a bad option came from."""
THRESHOLDS = {c["name"]: algo_thresholds()[c["name"]] for c in PAPER_CONSTRAINTS}
"""alpha_1 (dm) and alpha_2 (collisions per episode) of the paper's Table 1: ``algo=crllk``'s."""
AGENTS = {
    "CRLLK-D": ("algo=crllk", "action=discrete"),
    "PPO-D": ("algo=ppo", "action=discrete"),
    "CRLLK-C": ("algo=crllk", "action=continuous"),
    "PPO-C": ("algo=ppo", "action=continuous"),
}
"""The four agents of Table 1 as trainer overrides."""
PAPER_TABLE1 = {
    "CRLLK-D": {"J_clane": (0.66, 0.02), "J_coll": (0.17, 0.00), "J_R": (69.0, 0.6)},
    "PPO-D": {"J_clane": (0.99, 0.07), "J_coll": (0.38, 0.04), "J_R": (46.6, 3.2)},
    "CRLLK-C": {"J_clane": (0.31, 0.00), "J_coll": (0.05, 0.01), "J_R": (62.4, 22.2)},
    "PPO-C": {"J_clane": (1.04, 0.25), "J_coll": (0.34, 0.20), "J_R": (51.3, 14.8)},
}
"""The paper's Table 1 (mean ± std over two seeds, 100 test episodes)."""
PAPER_J_R_PER_METRE = 30.0
"""The original reward summed speed x cos(heading) per 30 Hz step: about 30 per metre."""
MAP_TASKS = ("zigzag", "obstacle_loop")
FIGURE_THRESHOLDS = (0.5, 0.75)
PIXEL_FRAMES, STATE_FRAMES = 500_000, 300_000
"""Default frames per run: the trainer's own defaults for each observation."""
SWEEP_TASKS = ("small_loop", "zigzag", "obstacle_loop")
SWEEP_LANE_WEIGHTS = (0.3, 1.0, 3.0)
"""Fixed λ_lane of the sweep's PPO-D runs (per dm of lane deviation)."""
SWEEP_COLLISION_WEIGHTS = (1.0, 4.0, 16.0, 64.0)
"""Fixed λ_coll of the sweep's PPO-D runs (per collision)."""


@dataclass(frozen=True)
class RunSpec:
    """One training run of an experiment."""

    agent: str
    task: str
    seed: int
    lane_threshold: float = THRESHOLDS["lane"]
    extra: tuple[str, ...] = ()
    tag: str = ""
    """Added to the run's directory name (fixed weights of a sweep run)."""

    def directory(self, root: Path) -> Path:
        return root / self.task / (f"{self.agent}{self.tag}-a{self.lane_threshold:g}"
                                   f"-seed{self.seed}")

    def log(self, root: Path) -> Path:
        return self.directory(root).parent / f"{self.directory(root).name}.log"

    def train_command(self, root: Path, settings: Settings) -> list[str]:
        return [sys.executable, "-m", "crllk.train", f"task={self.task}", *AGENTS[self.agent],
                f"obs={settings.obs}", f"seed={self.seed}",
                f"algo.constraints.lane.threshold={self.lane_threshold}",
                f"algo.constraints.collision.threshold={THRESHOLDS['collision']}",
                f"total_frames={settings.frames}", f"run_dir={self.directory(root)}",
                "resume=true", "progress=false", "threads=1", *settings.train_overrides,
                *self.extra]


@dataclass(frozen=True)
class Settings:
    """Budget and evaluation of an experiment."""

    frames: int = PIXEL_FRAMES
    seeds: tuple[int, ...] = (0, 1)
    episodes: int = 100
    obs: str = "pixels"
    jobs: int = 2
    runs_root: Path = Path("results/runs")
    results: Path = Path("results")
    eval_seed: int = EVALUATION_SEED
    command: str = ""
    train_overrides: tuple[str, ...] = ()
    agents: tuple[str, ...] = tuple(AGENTS)
    """The agents of Table 1 and the maps table (all four by default)."""
    sweep_tasks: tuple[str, ...] = SWEEP_TASKS
    lane_weights: tuple[float, ...] = SWEEP_LANE_WEIGHTS
    collision_weights: tuple[float, ...] = SWEEP_COLLISION_WEIGHTS
    robust_tasks: tuple[str, ...] = ("small_loop", "zigzag")
    """The maps of the robustness experiment."""
    conditions: tuple[str, ...] = ()
    """The robustness experiment's conditions (empty: all)."""


@dataclass
class Outcome:
    """Evaluations of the runs of an experiment, by run."""

    documents: dict[RunSpec, dict[str, Any]] = field(default_factory=dict)
    wall_s: float = 0.0


# ----- running ------------------------------------------------------------------------------
def trained_frames(run_dir: Path) -> int:
    """Frames in the run's last checkpoint; without one, those of its ``eval.json`` (a
    finished run kept without its checkpoint, as ``results/runs`` keeps them); else 0."""
    path = run_dir / CHECKPOINT_FILE
    if path.is_file():
        return int(torch.load(path, map_location="cpu", weights_only=False)["frames"])
    if (run_dir / EVAL_FILE).is_file():
        return int(read_eval_json(run_dir).get("source", {}).get("frames", 0))
    return 0


def evaluation_is_current(run_dir: Path, settings: Settings, name: str | None = None) -> bool:
    """Whether ``eval.json`` (or ``<name>.json``) evaluated the last checkpoint with these
    settings."""
    path = run_dir / (EVAL_FILE if name is None else f"{name}.json")
    if not path.is_file():
        return False
    document = json.loads(path.read_text())
    evaluation = document.get("evaluation", {})
    return (document.get("source", {}).get("frames") == trained_frames(run_dir)
            and evaluation.get("episodes") == settings.episodes
            and evaluation.get("seed") == settings.eval_seed
            and evaluation.get("deterministic") is False)


def run_parallel(commands: Sequence[tuple[list[str], Path]], jobs: int) -> list[str]:
    """Runs ``(command, log file)`` pairs, ``jobs`` at a time; returns the failures."""
    pending, running, failures = list(commands), [], []
    while pending or running:
        while pending and len(running) < jobs:
            command, log = pending.pop(0)
            log.parent.mkdir(parents=True, exist_ok=True)
            handle = log.open("a")
            print(f"  start: {' '.join(command[2:])}  (log: {log})", flush=True)
            running.append((subprocess.Popen(command, stdout=handle, stderr=subprocess.STDOUT,
                                             env=_child_env()), handle, command, log))
        time.sleep(0.5)
        for entry in list(running):
            process, handle, command, log = entry
            if process.poll() is not None:
                handle.close()
                running.remove(entry)
                if process.returncode != 0:
                    failures.append(f"{' '.join(command[2:])} exited {process.returncode}; "
                                    f"see {log}")
    return failures


def _child_env() -> dict[str, str]:
    """Each child uses one core: ``jobs`` children share the machine without oversubscribing."""
    return {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def train_and_evaluate(specs: Sequence[RunSpec], settings: Settings) -> Outcome:
    """Trains the unfinished runs, evaluates the unevaluated ones, returns every evaluation."""
    started = time.perf_counter()
    root = settings.runs_root
    to_train = [s for s in specs if trained_frames(s.directory(root)) < settings.frames]
    print(f"training {len(to_train)} of {len(specs)} runs ({settings.jobs} at a time)",
          flush=True)
    failures = run_parallel([(s.train_command(root, settings),
                              s.log(root)) for s in to_train],
                            settings.jobs)
    to_evaluate = [s for s in specs if not evaluation_is_current(s.directory(root), settings)]
    print(f"evaluating {len(to_evaluate)} of {len(specs)} runs", flush=True)
    failures += run_parallel(
        [([sys.executable, "-m", "crllk.evaluate", f"run={s.directory(root)}",
           f"episodes={settings.episodes}", f"seed={settings.eval_seed}"],
          s.log(root)) for s in to_evaluate], settings.jobs)
    if failures:
        raise RuntimeError("some runs failed:\n" + "\n".join(failures))
    documents = {s: read_eval_json(s.directory(root)) for s in specs}
    return Outcome(documents, time.perf_counter() - started)
