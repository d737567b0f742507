"""The runs of an experiment: what each one is, training them as trainer multiruns (Hydra's
joblib launcher, ``--jobs`` at a time), evaluating them, and reusing the finished ones."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from joblib import Parallel, delayed

from crllk.config import algo_thresholds
from crllk.errors import ConfigError
from crllk.evaluation.report import PAPER_CONSTRAINTS, aggregate, format_summary
from crllk.evaluation.runs import EVALUATION_ENVS, evaluate_run
from crllk.experiments.provenance import describe, stale_settings
from crllk.protocol import TEST_EPISODES, TEST_EVALUATION, TEST_MODE_EVALUATION, TEST_SEED
from crllk.training.runs import (
    EVAL_FILE,
    EXPECTED_ACTION,
    EXPECTED_DUTY,
    MODE,
    deployed_form,
    deployed_forms,
    has_policy,
    keep_policy,
    load_run_policy,
    read_eval_json,
)

SOURCE = "experiments"
"""How errors name where a bad option came from."""
THRESHOLDS = {c["name"]: algo_thresholds()[c["name"]] for c in PAPER_CONSTRAINTS}
"""alpha_1 (dm) and alpha_2 (collisions per episode) of the paper's Table 1: ``algo=crllk``'s."""
AGENTS = ("CRLLK-D", "PPO-D", "CRLLK-C", "PPO-C")
"""The four agents of Table 1: choices of the trainer's ``agent`` group (``crllk/conf/agent``),
each an ``algo`` and an ``action``."""
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
FIGURE_THRESHOLDS = (0.08, 0.12, 0.2, 0.5)
"""alpha_1 (dm) of Figure 1's CRLLK-D runs: values that bind on small_loop (its runs at 0.5
deviate about 0.15–0.2 dm), and the paper's 0.5."""
PIXEL_FRAMES, STATE_FRAMES = 500_000, 300_000
"""Default frames per run: the trainer's own defaults for each observation."""
SWEEP_TASKS = ("small_loop", "zigzag", "obstacle_loop")
SWEEP_LANE_WEIGHTS = (0.3, 1.0, 3.0)
"""Fixed λ_lane of the sweep's PPO-D runs (per dm of lane deviation)."""
SWEEP_COLLISION_WEIGHTS = (1.0, 4.0, 16.0, 64.0)
"""Fixed λ_coll of the sweep's PPO-D runs (per collision)."""
MODE_EVALUATION = TEST_MODE_EVALUATION
"""Each run's test evaluation of its deployed policy (``<run>/test-mode.json``), the one
``crllk.export`` writes for the robot: a discrete run's expected duties, a continuous run's
expected action (:func:`crllk.training.runs.deployed_form`)."""


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
    task_file: str = ""
    """A task or Duckietown map file (path) to train on instead of the named ``task``."""

    @property
    def task_folder(self) -> str:
        """The folder of the run's map under the runs root: the task's name, or the stem of
        its ``task_file``."""
        return Path(self.task_file).stem if self.task_file else self.task

    def directory(self, root: Path) -> Path:
        return root / self.task_folder / (f"{self.agent}{self.tag}-a{self.lane_threshold:g}"
                                          f"-seed{self.seed}")


@dataclass(frozen=True)
class Settings:
    """Budget and evaluation of an experiment: its runs train (and choose nothing) on the
    validation seed; its tables report their evaluation on ``eval_seed``, the test seed
    (:mod:`crllk.protocol`), ``episodes`` per run."""

    frames: int = PIXEL_FRAMES
    seeds: tuple[int, ...] = (0, 1)
    """Training seeds of every run but the CRLLK agents' in Table 1, the maps and traffic."""
    crllk_seeds: tuple[int, ...] = (0, 1, 2)
    """Training seeds of the CRLLK agents in Table 1, the maps and traffic tables (their claims
    rest on three; the baselines keep two)."""
    episodes: int = TEST_EPISODES
    obs: str = "pixels"
    jobs: int = 2
    runs_root: Path = Path("results/runs")
    results: Path = Path("results")
    eval_seed: int = TEST_SEED
    command: str = ""
    train_overrides: tuple[str, ...] = ()
    agents: tuple[str, ...] = tuple(AGENTS)
    """The agents of Table 1 and the maps table (all four by default)."""
    sweep_tasks: tuple[str, ...] = SWEEP_TASKS
    lane_weights: tuple[float, ...] = SWEEP_LANE_WEIGHTS
    collision_weights: tuple[float, ...] = SWEEP_COLLISION_WEIGHTS
    figure_thresholds: tuple[float, ...] = FIGURE_THRESHOLDS
    """alpha_1 values (dm) of Figure 1's runs."""
    robust_tasks: tuple[str, ...] = ("small_loop", "zigzag")
    """The maps of the robustness experiment."""
    conditions: tuple[str, ...] = ()
    """The robustness experiment's conditions (empty: all)."""


def agent_seeds(settings: Settings, agent: str) -> tuple[int, ...]:
    """The training seeds of ``agent`` in Table 1, the maps and traffic tables."""
    return settings.crllk_seeds if agent.startswith("CRLLK") else settings.seeds


@dataclass
class Outcome:
    """Evaluations of the runs of an experiment, by run."""

    documents: dict[RunSpec, dict[str, Any]] = field(default_factory=dict)
    wall_s: float = 0.0
    modes: dict[RunSpec, dict[str, Any]] = field(default_factory=dict)
    """The evaluations of the deployed policy (:data:`MODE_EVALUATION`), of the runs that
    have one."""
    trained: int = 0
    """How many of the runs this invocation trained (the others were finished before it)."""
    evaluated: int = 0
    """How many evaluations (sampled and mode) this invocation made (the others were reused)."""


EXPECTED_FORMS = {EXPECTED_DUTY: "expected duties", EXPECTED_ACTION: "expected action"}
"""The deployed policies' forms that replaced the mode, and how tables name them."""


def _forms(entries: Iterable[Mapping[str, Any] | None]) -> set[str]:
    return {form for entry in entries if entry is not None
            for form in entry.get("deployed", (MODE,))}


def expected_forms_deployed(entries: Iterable[Mapping[str, Any]]) -> bool:
    """Whether any of these aggregates of deployed policies (``"mode"`` entries of a table)
    played an expected form (:data:`EXPECTED_FORMS`): their tables then describe the deployed
    policy as :func:`deployed_note` does, and older tables keep calling it the mode."""
    return bool(_forms(entries) & set(EXPECTED_FORMS))


def mode_aggregate(documents: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """:func:`~crllk.evaluation.report.aggregate` of deployed-policy evaluations, with how they
    acted (``"deployed"``: :func:`deployed_forms`)."""
    return {**aggregate(documents), "deployed": deployed_forms(documents)}


def deployed_label(entries: Iterable[Mapping[str, Any] | None]) -> str:
    """How a table names its deployed policies (``"mode"`` aggregates, None where missing):
    by what they played; tables of argmax evaluations keep calling them the mode."""
    forms = _forms(entries)
    if not forms & set(EXPECTED_FORMS):
        return "deployed policy (mode)"
    if len(forms) == 1:
        return f"deployed policy ({EXPECTED_FORMS[forms.pop()]})"
    return "deployed policy"


def deployed_note(entries: Iterable[Mapping[str, Any] | None]) -> str:
    """What a table's *deployed policy* is, once its discrete agents deploy expected duties:
    a continuous agent's expected action where its evaluations played it, else its mode (both,
    where some evaluations predate the expected action)."""
    forms = _forms(entries)
    gaussian = ("expected action (the mean of its tanh-squashed Gaussian's actions)"
                if EXPECTED_ACTION in forms else "mode")
    if EXPECTED_ACTION in forms and MODE in forms:
        gaussian += ", or its mode in the evaluations that predate it"
    return ("the policy `crllk.export` writes for the robot: a discrete agent's expected "
            "wheel duties (its three duty pairs weighted by their probabilities), a "
            f"continuous agent's {gaussian}")


# ----- running ------------------------------------------------------------------------------
def trained_frames(run_dir: Path) -> int:
    """Frames of the run's last policy (its checkpoint, or the ``policy.pt`` that
    ``results/runs`` keeps); without either, those of its ``eval.json``; else 0."""
    if has_policy(run_dir):
        return int(load_run_policy(run_dir)["frames"])
    if (run_dir / EVAL_FILE).is_file():
        return int(read_eval_json(run_dir).get("source", {}).get("frames", 0))
    return 0


def evaluation_is_current(run_dir: Path, settings: Settings, name: str,
                          deterministic: bool = False) -> bool:
    """Whether ``<name>.json`` evaluated the last policy with these settings and
    ``crllk.evaluate``'s simulations (of the sampled policy, or with ``deterministic`` of the
    deployed one, in its present form: a discrete run's mode evaluated before its expected
    duties were deployed is not current)."""
    path = run_dir / f"{name}.json"
    if not path.is_file():
        return False
    document = json.loads(path.read_text())
    evaluation, source = document.get("evaluation", {}), document.get("source", {})
    deployed = (not deterministic or evaluation.get("deployed", MODE)
                == deployed_form(source.get("action", "")))
    return (source.get("frames") == trained_frames(run_dir)
            and evaluation.get("episodes") == settings.episodes
            and evaluation.get("seed") == settings.eval_seed
            and evaluation.get("num_envs", EVALUATION_ENVS) == EVALUATION_ENVS
            and evaluation.get("deterministic") is deterministic and deployed)


def sweep_commands(specs: Sequence[RunSpec], settings: Settings) -> list[list[str]]:
    """The trainer multiruns (``python -m crllk.train -m``) that train ``specs``: runs that
    differ only in agent, map and seed are one sweep over ``agent``, ``task`` and ``seed``, its
    ``run_dir`` interpolating all three. Runs that are not every combination of those are split
    into sweeps that are: by agent, then by agent and map. Runs on a map file sweep apart, one
    file each (``task_file=PATH``, its folder written out in ``run_dir``)."""
    groups: dict[tuple, list[RunSpec]] = {}
    for spec in specs:
        key = (spec.lane_threshold, spec.extra, spec.tag, spec.task_file)
        groups.setdefault(key, []).append(spec)
    return [_sweep_command(part, settings) for members in groups.values()
            for part in _products(members)]


def _products(specs: Sequence[RunSpec]) -> list[list[RunSpec]]:
    """``specs`` as few parts as possible, each every agent × map × seed of its own."""
    def is_product(part: Sequence[RunSpec]) -> bool:
        axes = [{getattr(s, a) for s in part} for a in ("agent", "task", "seed")]
        return len(part) == len(axes[0]) * len(axes[1]) * len(axes[2])

    if is_product(specs):
        return [list(specs)]
    parts = []
    for agent in dict.fromkeys(s.agent for s in specs):
        mine = [s for s in specs if s.agent == agent]
        parts += [mine] if is_product(mine) else [
            [s for s in mine if s.task == task] for task in dict.fromkeys(s.task for s in mine)]
    return parts


def _sweep_command(specs: Sequence[RunSpec], settings: Settings) -> list[str]:
    spec = specs[0]
    name = spec.directory(settings.runs_root).name.rsplit("-seed", 1)[0].replace(
        spec.agent, "${hydra:runtime.choices.agent}", 1)

    def values(axis: str) -> str:
        return ",".join(str(v) for v in dict.fromkeys(getattr(s, axis) for s in specs))

    # a map file leaves the composed task (and ${task.name}) the default one: its folder here
    task, folder = ((f"task_file={spec.task_file}", spec.task_folder) if spec.task_file
                    else (f"task={values('task')}", "${task.name}"))
    return [sys.executable, "-m", "crllk.train", "-m", f"agent={values('agent')}",
            task, f"seed={values('seed')}",
            *_training_overrides(spec, settings),
            f"run_dir={settings.runs_root}/{folder}/{name}-seed${{seed}}",
            "resume=true", "progress=false", "threads=1", "workers=1",
            f"hydra.launcher.n_jobs={settings.jobs}", *settings.train_overrides, *spec.extra]


def _training_overrides(spec: RunSpec, settings: Settings) -> list[str]:
    """The trainer settings every run of ``spec``'s sweep shares, besides its own extras."""
    return [f"obs={settings.obs}", f"algo.constraints.lane.threshold={spec.lane_threshold}",
            f"algo.constraints.collision.threshold={THRESHOLDS['collision']}",
            f"total_frames={settings.frames}"]


def run_overrides(spec: RunSpec, settings: Settings) -> list[str]:
    """The trainer overrides of the one run ``spec`` (as its sweep trains it)."""
    task = f"task_file={spec.task_file}" if spec.task_file else f"task={spec.task}"
    return [f"agent={spec.agent}", task, f"seed={spec.seed}",
            *_training_overrides(spec, settings), *settings.train_overrides, *spec.extra]


def check_provenance(specs: Sequence[RunSpec], settings: Settings) -> None:
    """Refuses to reuse or resume a run (finished or not) trained with other settings than
    its experiment trains now (:func:`crllk.experiments.provenance.stale_settings`).

    Raises:
        ConfigError: one line naming each such run and its settings.
    """
    stale = []
    for spec in specs:
        run_dir = spec.directory(settings.runs_root)
        if (run_dir / "config.yaml").is_file():
            differences = stale_settings(run_dir, run_overrides(spec, settings),
                                         task_file=spec.task_file or None)
            if differences:
                stale.append(describe(run_dir, differences))
    if stale:
        raise ConfigError(SOURCE, "runs", "trained with other settings than this experiment "
                          "trains now; move them aside to train them again: "
                          + "; ".join(stale))


def run_sweeps(commands: Sequence[list[str]], log: Path) -> None:
    """Runs the trainer multiruns one after another (each runs ``hydra.launcher.n_jobs`` of
    its jobs at a time), their output appended to ``log``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    for command in commands:
        print(f"  sweep: {' '.join(command[2:])}  (log: {log})", flush=True)
        with log.open("a") as handle:
            handle.write(f"$ {' '.join(command[2:])}\n")
            handle.flush()
            subprocess.run(command, stdout=handle, stderr=subprocess.STDOUT, env=_child_env(),
                           check=False)


def _child_env() -> dict[str, str]:
    """Each job uses one core: ``jobs`` of them share the machine without oversubscribing."""
    return {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def evaluate_runs(requests: Sequence[tuple[Path, dict[str, Any]]], settings: Settings) -> None:
    """Evaluates ``(run_dir, evaluate_run keyword arguments)`` pairs, ``jobs`` processes at a
    time (joblib), each on the experiment's (test) seed with ``settings.episodes`` episodes."""
    Parallel(n_jobs=settings.jobs)(
        delayed(_evaluate)(run_dir, episodes=settings.episodes, seed=settings.eval_seed,
                           **kwargs) for run_dir, kwargs in requests)


def _evaluate(run_dir: Path, **kwargs: Any) -> None:
    torch.set_num_threads(1)  # each job one core: its simulations in its own process too
    print(format_summary(evaluate_run(run_dir, workers=1, **kwargs)), flush=True)


def train_and_evaluate(specs: Sequence[RunSpec], settings: Settings,
                       policies: Sequence[RunSpec] = ()) -> Outcome:
    """Trains the unfinished runs (trainer multiruns), and those of ``policies`` that are
    finished but kept without a policy (trained again: their policy is needed); evaluates the
    untested ones on the test seed (sampled policy and mode, once per finished run); returns
    every test evaluation."""
    started = time.perf_counter()
    root = settings.runs_root
    to_train = [s for s in specs if trained_frames(s.directory(root)) < settings.frames
                or (s in policies and not has_policy(s.directory(root)))]
    check_provenance(specs, settings)
    print(f"training {len(to_train)} of {len(specs)} runs ({settings.jobs} at a time)",
          flush=True)
    log = root / "sweeps.log"
    run_sweeps(sweep_commands(to_train, settings), log)
    unfinished = [s for s in to_train if trained_frames(s.directory(root)) < settings.frames
                  or not has_policy(s.directory(root))]
    if unfinished:
        raise RuntimeError("some runs did not finish (see " + str(log) + "):\n" + "\n".join(
            str(s.directory(root)) for s in unfinished))
    to_evaluate = [s for s in specs
                   if not evaluation_is_current(s.directory(root), settings, TEST_EVALUATION)]
    for spec in specs:  # runs trained before the trainer kept its policy beside the checkpoints
        keep_policy(spec.directory(root))
    # the deployed policy of every run that has one
    modes = [s for s in specs if has_policy(s.directory(root))
             and not _mode_is_current(s.directory(root), settings)]
    print(f"test evaluation of {len(to_evaluate)} of {len(specs)} runs, and of the deployed "
          f"policy of {len(modes)}", flush=True)
    evaluate_runs([(s.directory(root), {"name": TEST_EVALUATION}) for s in to_evaluate]
                  + [(s.directory(root), {"name": MODE_EVALUATION, "deterministic": True})
                     for s in modes], settings)
    documents = {s: read_eval_json(s.directory(root), TEST_EVALUATION) for s in specs}
    mode_documents = {s: json.loads((s.directory(root) / f"{MODE_EVALUATION}.json").read_text())
                      for s in specs if _mode_is_current(s.directory(root), settings)}
    return Outcome(documents, time.perf_counter() - started, mode_documents,
                   trained=len(to_train), evaluated=len(to_evaluate) + len(modes))


def _mode_is_current(run_dir: Path, settings: Settings) -> bool:
    return evaluation_is_current(run_dir, settings, MODE_EVALUATION, deterministic=True)
