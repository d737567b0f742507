"""``python -m crllk.experiments peers --obs state``: crllk's constrained learners beside a peer
library's on the same tasks, judged by the same test evaluation.

- crllk: CRLLK-D (PPO-Lagrangian, dual ascent), its PID variant (``algo.multiplier=pid``),
  CRLLK-C (continuous actions, the peers' action space) and SAC-Lagrangian
  (``algo=sac_lagrangian``), with the trainer's defaults (the PPO learners' teacher, encounter
  spawns on maps with obstacles: each run's aids named in the table, read from the run);
- OmniSafe: PPOLag and CPPOPID with OmniSafe's default settings, trained in their own Python
  (``make peers``; ``peers/omnisafe/train.py``) on the task served by
  :mod:`crllk.peers.env_server`, which gives them one cost, the constraints' normalised sum
  with limit 1 (a sufficient condition for both; OmniSafe takes one constraint).

Every run is evaluated on the test seed, its sampled policy and its deployed one (the mode, or
the Gaussian mean); the table adds training frames/s and the time to both constraints: the
first training frame from which the last :data:`WINDOW_EPISODES` training episodes meet both
thresholds, read from ``metrics.csv`` (crllk) or the served episodes (``episodes.csv``, peers).
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from joblib import Parallel, delayed

from crllk.errors import ConfigError
from crllk.evaluation.peer_runs import PEER_EPISODES, evaluate_peer, read_peer
from crllk.evaluation.report import aggregate, format_summary
from crllk.evaluation.runs import EVALUATION_ENVS
from crllk.experiments.runs import (
    SOURCE,
    THRESHOLDS,
    RunSpec,
    Settings,
    train_and_evaluate,
)
from crllk.experiments.seeds import seed_cells
from crllk.experiments.tables import invocation, invocation_note, settings_dict, write_documents
from crllk.files import read_csv_rows
from crllk.paths import SOURCE_ROOT
from crllk.protocol import TEST_EVALUATION, TEST_MODE_EVALUATION
from crllk.saved_config import read_run_config

TASKS = ("small_loop", "obstacle_loop")
PEER_ALGOS = ("PPOLag", "CPPOPID")
"""OmniSafe's algorithms in the table."""
PEER_PYTHON = SOURCE_ROOT / ".venv-omnisafe" / "bin" / "python"
PEER_TRAINER = SOURCE_ROOT / "peers" / "omnisafe" / "train.py"
PEER_EPOCH_FRAMES = 20_000
"""Frames per OmniSafe epoch (its default for PPOLag and CPPOPID): a peer run's budget is a
whole number of them."""
WINDOW_EPISODES = 100
"""Training episodes the time to both constraints averages over."""
PID_GAINS = ("algo.constraints.lane.kp=0.5", "algo.constraints.collision.kp=5.0")
"""The PID variant's proportional gains: ten times each multiplier's integral gain (its dual
step size); no derivative term. Not tuned."""


@dataclass(frozen=True)
class Contender:
    """A row of the table: a crllk run configuration, or a peer library's algorithm."""

    name: str
    agent: str = "CRLLK-D"
    tag: str = ""
    extra: tuple[str, ...] = ()
    peer: str = ""
    """The peer library's algorithm (empty: a crllk learner)."""

    def spec(self, task: str, seed: int) -> RunSpec:
        return RunSpec(self.agent, task, seed, tag=self.tag, extra=self.extra)

    def directory(self, root: Path, task: str, seed: int) -> Path:
        if self.peer:
            return root / task / f"OmniSafe-{self.peer}-a{THRESHOLDS['lane']:g}-seed{seed}"
        return self.spec(task, seed).directory(root)


CONTENDERS = (
    Contender("CRLLK-D"),
    Contender("CRLLK-D PID", tag="-pid", extra=("algo.multiplier=pid", *PID_GAINS)),
    Contender("CRLLK-C", agent="CRLLK-C"),
    Contender("SAC-Lagrangian-D", tag="-sac", extra=("algo=sac_lagrangian",)),
    *(Contender(f"OmniSafe {algo}", peer=algo) for algo in PEER_ALGOS),
)


# ----- peers ---------------------------------------------------------------------------------
def peer_command(algo: str, task: str, seed: int, frames: int, run_dir: Path) -> list[str]:
    return [str(PEER_PYTHON), str(PEER_TRAINER), "--algo", algo, "--task", task,
            "--seed", str(seed), "--frames", str(frames), "--run-dir", str(run_dir),
            "--steps-per-epoch", str(PEER_EPOCH_FRAMES)]


def peer_frames(run_dir: Path) -> int:
    """Frames of a finished peer run (0: not finished)."""
    try:
        return int(read_peer(run_dir)["frames"]) if (run_dir / "policy.npz").is_file() else 0
    except ConfigError:
        return 0


def train_peers(runs: Sequence[tuple[str, str, int, Path]], settings: Settings) -> int:
    """Trains the unfinished ``(algo, task, seed, run_dir)`` peer runs, ``jobs`` at a time, each
    one's output in ``<run_dir>.log``; returns how many it trained."""
    if settings.frames % PEER_EPOCH_FRAMES:
        raise ConfigError(SOURCE, "--frames", f"peers: a whole number of OmniSafe epochs of "
                          f"{PEER_EPOCH_FRAMES:,} frames, got {settings.frames:,}")
    todo = [r for r in runs if peer_frames(r[3]) < settings.frames]
    if todo and not PEER_PYTHON.is_file():
        raise ConfigError(SOURCE, "peers", f"{PEER_PYTHON} is missing: run `make peers` first")
    print(f"training {len(todo)} of {len(runs)} peer runs ({settings.jobs} at a time)",
          flush=True)

    def train(algo: str, task: str, seed: int, run_dir: Path) -> None:
        run_dir.parent.mkdir(parents=True, exist_ok=True)
        with run_dir.parent.joinpath(run_dir.name + ".log").open("a") as log:
            subprocess.run(peer_command(algo, task, seed, settings.frames, run_dir),
                           stdout=log, stderr=subprocess.STDOUT, check=False, cwd=SOURCE_ROOT)

    Parallel(n_jobs=settings.jobs, backend="threading")(delayed(train)(*r) for r in todo)
    unfinished = [str(r[3]) for r in todo if peer_frames(r[3]) == 0]
    if unfinished:
        raise RuntimeError("some peer runs did not finish (see their .log):\n"
                           + "\n".join(unfinished))
    return len(todo)


def evaluate_peers(run_dirs: Sequence[Path], settings: Settings) -> int:
    """Test evaluations (sampled and mean) of the peer runs that lack a current one; returns
    how many it made."""
    requests = [(d, name, deterministic) for d in run_dirs
                for name, deterministic in ((TEST_EVALUATION, False),
                                            (TEST_MODE_EVALUATION, True))
                if not _peer_evaluation_is_current(d, settings, name, deterministic)]

    def evaluate(run_dir: Path, name: str, deterministic: bool) -> None:
        document = evaluate_peer(run_dir, episodes=settings.episodes, seed=settings.eval_seed,
                                 deterministic=deterministic, name=name)
        print(format_summary(document), flush=True)

    Parallel(n_jobs=settings.jobs)(delayed(evaluate)(*r) for r in requests)
    return len(requests)


def _peer_evaluation_is_current(run_dir: Path, settings: Settings, name: str,
                                deterministic: bool) -> bool:
    path = run_dir / f"{name}.json"
    if not path.is_file():
        return False
    document = json.loads(path.read_text())
    evaluation = document.get("evaluation", {})
    return (document["source"].get("frames") == peer_frames(run_dir)
            and evaluation.get("episodes") == settings.episodes
            and evaluation.get("seed") == settings.eval_seed
            and evaluation.get("num_envs") == EVALUATION_ENVS
            and evaluation.get("deterministic") is deterministic)


# ----- training curves -----------------------------------------------------------------------
def training_rows(run_dir: Path) -> list[dict[str, str]]:
    """The run's training statistics: ``metrics.csv`` rows (crllk, one per iteration) or
    ``episodes.csv`` rows (a peer, one per episode); both carry frames, time_s, episodes and
    each constraint's metric."""
    path = run_dir / (PEER_EPISODES if (run_dir / PEER_EPISODES).is_file() else "metrics.csv")
    return read_csv_rows(path)[1]


def time_to_constraints(rows: Sequence[Mapping[str, str]], thresholds: Mapping[str, float],
                        window: int = WINDOW_EPISODES) -> tuple[int, float] | None:
    """``(frames, seconds)`` at the first row from which the training episodes of the rows
    before it, back to at least ``window`` episodes, meet both thresholds (episode-weighted
    means); None if never."""
    collected: list[tuple[int, float, float]] = []  # (episodes, J_clane, J_coll)
    for row in rows:
        episodes = int(float(row["episodes"] or 0))
        if episodes == 0:
            continue
        collected.append((episodes, float(row["J_clane"]), float(row["J_coll"])))
        total, lane, coll = 0, 0.0, 0.0
        for count, lane_value, coll_value in reversed(collected):
            total += count
            lane += count * lane_value
            coll += count * coll_value
            if total >= window:
                break
        if (total >= window and lane / total <= thresholds["lane"]
                and coll / total <= thresholds["collision"]):
            return int(float(row["frames"])), float(row["time_s"])
    return None


def training_speed(rows: Sequence[Mapping[str, str]]) -> float:
    """Frames per second of wall time over the whole training."""
    last = rows[-1]
    return float(last["frames"]) / float(last["time_s"])


def aids_of(run_dir: Path, rows: Sequence[Mapping[str, str]]) -> str:
    """The training aids a run used, read from the run itself: encounter spawns (on a map with
    obstacles, where they apply) and the teacher (an imitation term that was not zero in
    ``metrics.csv``, on any map); "none" for a peer's run."""
    config = run_dir / "config.yaml"
    if not config.is_file():
        return "none"
    stored = read_run_config(config)
    aids = []
    if float(stored.get("encounters", 0) or 0) > 0 and stored.task.map.get("objects"):
        aids.append(f"encounter spawns {float(stored.encounters):g}")
    if any(float(row.get("loss_imitation") or 0.0) != 0.0 for row in rows):
        aids.append("teacher")
    return ", ".join(aids) or "none"


# ----- the experiment ------------------------------------------------------------------------
def peers(settings: Settings) -> list[Path]:
    """Trains what is missing, evaluates on the test seed, writes ``peers.{json,md}``."""
    if settings.obs != "state":
        raise ConfigError(SOURCE, "--obs", "peers: the peer library's agents read state "
                          "features only: give --obs state")
    started = time.perf_counter()
    root = settings.runs_root
    crllk_contenders = [contender for contender in CONTENDERS if not contender.peer]
    specs = [contender.spec(task, seed) for task in TASKS for contender in crllk_contenders
             for seed in settings.seeds]
    outcome = train_and_evaluate(specs, settings)
    peer_runs = [(contender.peer, task, seed, contender.directory(root, task, seed))
                 for task in TASKS for contender in CONTENDERS if contender.peer
                 for seed in settings.seeds]
    outcome.trained += train_peers(peer_runs, settings)
    outcome.evaluated += evaluate_peers([r[3] for r in peer_runs], settings)
    outcome.wall_s = time.perf_counter() - started  # the peers' training and evaluation too
    document = peers_document(settings, outcome)
    document["runs_total"] += len(peer_runs)
    return write_documents(settings, "peers", document, peers_markdown(document))


def peers_document(settings: Settings, outcome: Any) -> dict[str, Any]:
    """Per map and learner: the test evaluations' aggregate (sampled and mode), per seed the
    training speed, time to both constraints and the aids; per map the best tracker."""
    root = settings.runs_root
    maps: dict[str, Any] = {}
    for task in TASKS:
        entries = {}
        for contender in CONTENDERS:
            dirs = [contender.directory(root, task, seed) for seed in settings.seeds]
            documents = [json.loads((d / f"{TEST_EVALUATION}.json").read_text()) for d in dirs]
            modes = [json.loads((d / f"{TEST_MODE_EVALUATION}.json").read_text()) for d in dirs]
            entry = aggregate(documents)
            entry["mode"] = aggregate(modes)
            entry["training"] = {}
            for seed, run_dir in zip(settings.seeds, dirs, strict=True):
                rows = training_rows(run_dir)
                entry["training"][str(seed)] = {
                    "frames_per_s": training_speed(rows),
                    "time_to_constraints": time_to_constraints(rows, THRESHOLDS),
                    "aids": aids_of(run_dir, rows)}
            entries[contender.name] = entry
        maps[task] = {"learners": entries, "best": best_tracker(entries)}
    return {"title": "crllk's constrained learners and OmniSafe's, from state",
            "thresholds": THRESHOLDS, "settings": settings_dict(settings),
            **invocation(outcome), "window_episodes": WINDOW_EPISODES, "maps": maps}


def worst_ratio(entry: Mapping[str, Any]) -> float:
    """The largest ``metric / threshold`` over seeds and both constraints (at most 1: every seed
    meets both)."""
    return max(max(entry["J_clane"]["values"]) / THRESHOLDS["lane"],
               max(entry["J_coll"]["values"]) / THRESHOLDS["collision"])


def best_tracker(entries: Mapping[str, Mapping[str, Any]]) -> str:
    """The learner whose worst seed comes closest to (or furthest inside) both thresholds, its
    sampled policy judged; ties go to the larger mean J_R."""
    return min(entries, key=lambda name: (round(worst_ratio(entries[name]), 3),
                                          -entries[name]["J_R"]["mean"]))


def peers_markdown(document: Mapping[str, Any]) -> str:
    thresholds, settings = document["thresholds"], document["settings"]
    lines = [f"# {document['title']}", "",
             f"α1 = {thresholds['lane']} dm, α2 = {thresholds['collision']}. Each cell: J_clane "
             "(dm) / J_coll / J_R (m) of one training run on the test seed, with the 95 % "
             "intervals of the constraints' metrics; marks: both constraints hold on the point "
             "estimate, then at the 95 % upper bound. Speed: training frames per second of "
             "wall time (runs may have run on different days and beside other work, and a "
             "peer steps one simulation behind a JSON pipe: a rough guide only). To "
             "constraints: the first training frame from "
             f"which the last {document['window_episodes']} training episodes meet both "
             "thresholds.", "",
             f"- Observation: `{settings['obs']}`; budget {settings['frames']:,} frames per run; "
             f"{settings['episodes']} test episodes per run from spawn seed "
             f"{settings['eval_seed']} (the test seed).",
             f"- Command: `{settings['command']}` ({invocation_note(document)}).",
             f"- Machine: {settings['machine']}.",
             "- OmniSafe's algorithms train with its default settings and one cost, "
             "lane/(α1·horizon) + collisions/α2 per step with limit 1 per episode "
             "(`crllk/peers/env_server.py`): meeting it implies both constraints, so their "
             "budget is tighter than crllk's learners'.", ""]
    for task, table in document["maps"].items():
        lines += [f"## {task}", "",
                  f"Best constraint tracker (worst seed's largest metric/threshold, lowest): "
                  f"**{table['best']}**.", "",
                  "| learner | seed | sampled policy | deployed policy | frames/s | to "
                  "constraints | aids |", "| --- | --- | --- | --- | --- | --- | --- |"]
        for name, entry in table["learners"].items():
            sampled = seed_cells(entry, thresholds)
            mode = seed_cells(entry["mode"], thresholds)
            for seed, cell in sorted(sampled.items()):
                training = entry["training"][str(seed)]
                reached = training["time_to_constraints"]
                when = (f"{reached[0] / 1000:.0f}k frames, {reached[1] / 60:.1f} min"
                        if reached else "never")
                lines.append(f"| {name} | {seed} | {cell} | {mode[seed]} | "
                             f"{training['frames_per_s']:.0f} | {when} | {training['aids']} |")
        lines.append("")
    return "\n".join(lines)


__all__ = ["CONTENDERS", "peers", "peers_markdown", "time_to_constraints", "worst_ratio"]
