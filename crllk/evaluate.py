"""Evaluate trained runs (or the scripted lane follower) with the paper's metrics.

    python -m crllk.evaluate run=runs/small_loop/crllk-discrete-state-seed0 episodes=100
    python -m crllk.evaluate 'runs=[runs/a,runs/b]' episodes=100 out=results/ab.json
    python -m crllk.evaluate follower=true task=small_loop episodes=100
    python -m crllk.evaluate teacher=true task=obstacle_loop episodes=100   # the swerving teacher
    python -m crllk.evaluate run=... episodes=100 record=true record_episodes=2 [viewer=spawn]

Each run's checkpoint plays ``episodes`` seeded episodes (episode k in sub-environment
k mod ``num_envs``, spawns from ``seed``, by default the run's evaluation seed, never a
training seed) with its policy as trained: actions are sampled, from a torch generator seeded
with the same seed, so the numbers are reproducible (``deterministic=true`` takes the policy's
mode instead). The multipliers enforce the constraints on the sampled policy, the one PPO
trains; its mode is another policy, and with three discrete actions a much worse one: a policy
that steers by mixing turns and straight steps loses the mix. The result goes
to ``<run>/eval.json``: J_R (m), J_clane (dm), J_coll, episode length, the action histogram,
termination reasons and one row per episode. Several runs also print (and with ``out=`` write)
mean ± std across runs, the paper's way of reporting seeds. ``record=true`` also records
``record_episodes`` episodes of each run with rerun to ``<run>/recordings/eval.rrd``.
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from crllk.actions import DISCRETE_NAMES
from crllk.checkpoint import atomic_write_text
from crllk.envs import make_env
from crllk.episodes import summarise
from crllk.errors import ConfigError
from crllk.evaluation import EvaluationResult, run_episodes
from crllk.follower import FollowerPolicy
from crllk.runs import EVAL_FILE, load_actor, load_run_config
from crllk.train import build_env

SOURCE = "evaluate"
DEFAULT_SEED = 1_000_000
"""Spawn seed of evaluations without a run (the follower), as ``eval.seed`` of training."""
CONTINUOUS_BINS = np.linspace(-1.0, 1.0, 11)
"""Edges of the continuous action histogram (velocity and steering lie in [-1, 1])."""
METRICS = ("J_R", "J_clane", "J_coll", "episode_length")


@dataclass
class EvaluateConfig:
    """Command-line settings (``key=value``)."""

    run: str | None = None
    runs: list[str] = field(default_factory=list)
    follower: bool = False
    teacher: bool = False
    task: str = "small_loop"
    episodes: int = 100
    deterministic: bool = False
    seed: int | None = None
    num_envs: int = 10
    threads: int = 1
    out: str | None = None
    record: bool = False
    record_episodes: int = 1
    viewer: str = "none"
    lane_threshold: float = 0.5
    collision_threshold: float = 0.02

    def run_dirs(self) -> list[Path]:
        return [Path(r) for r in ([self.run] if self.run else []) + list(self.runs)]


# ----- one evaluation ----------------------------------------------------------------------
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
               "direction": _at(result.directions, k), "hit_object": _at(result.hit_objects, k)}
        if action == "discrete":
            counts = np.bincount(np.asarray(actions).reshape(-1).astype(np.int64),
                                 minlength=len(DISCRETE_NAMES))
            row["actions"] = dict(zip(DISCRETE_NAMES, counts.tolist(), strict=True))
        rows.append(row)
    return rows


def _at(values: Sequence[Any], k: int) -> Any:
    return values[k] if k < len(values) else None


def breakdown(result: EvaluationResult, objects: Sequence[Any] = ()) -> dict[str, Any]:
    """The metrics per start direction of the loop, and how many episodes ended on each
    obstacle (``objects``: the map's, to name them by kind and position)."""
    by_direction = {}
    for direction in ("intended", "reverse"):
        chosen = [e for e, d in zip(result.episodes, result.directions, strict=True)
                  if d == direction]
        if chosen:
            by_direction[direction] = summarise(chosen).as_row()
    hits: dict[str, int] = {}
    for index in result.hit_objects:
        if index is not None:
            obj = objects[index] if index < len(objects) else None
            name = f"{index}" if obj is None else f"{index} {obj.kind} ({obj.x:.2f}, {obj.y:.2f})"
            hits[name] = hits.get(name, 0) + 1
    return {"by_direction": by_direction, "collisions_by_object": dict(sorted(hits.items()))}


def result_document(result: EvaluationResult, action: str, *, thresholds: dict[str, float],
                    settings: dict[str, Any], source: dict[str, Any],
                    objects: Sequence[Any] = ()) -> dict[str, Any]:
    """The ``eval.json`` content of one evaluation (``objects``: the map's, named in the
    breakdown of collisions)."""
    s = result.summary
    rows = episode_rows(result, action)
    summary = {"J_R": s.J_R, "J_clane": s.J_clane, "J_coll": s.J_coll,
               "episode_length": s.length,
               "satisfied": bool(s.J_clane <= thresholds["lane"]
                                 and s.J_coll <= thresholds["collision"])}
    return {"source": source, "evaluation": settings, "thresholds": thresholds,
            "summary": summary, "action_histogram": action_histogram(result.actions, action),
            "terminations": dict(Counter(row["termination"] for row in rows)),
            "breakdown": breakdown(result, objects),
            "episodes": rows}


def evaluate_run(run_dir: str | Path, *, episodes: int, deterministic: bool = False,
                 seed: int | None = None, num_envs: int = 10) -> dict[str, Any]:
    """Plays the run's checkpoint and writes ``<run_dir>/eval.json``; returns its content."""
    config = load_run_config(run_dir)
    seed = config.eval.seed if seed is None else seed
    env = build_env(config, num_envs=num_envs, seed=seed)
    try:
        actor, info = load_actor(run_dir, env)
        result = run_episodes(env, actor, episodes, deterministic=deterministic,
                              sample_seed=seed)
    finally:
        env.close()
    source = {"run_dir": str(run_dir), "task": config.task_name, "algo": config.algo.name,
              "action": config.action.name, "obs": config.obs.name, "train_seed": config.seed,
              **info}
    settings = {"episodes": episodes, "seed": seed, "num_envs": num_envs,
                "deterministic": deterministic}
    thresholds = {"lane": config.algo.lane.threshold,
                  "collision": config.algo.collision.threshold}
    document = result_document(result, config.action.name, thresholds=thresholds,
                               settings=settings, source=source,
                               objects=env.config.map.objects)
    atomic_write_text(Path(run_dir) / EVAL_FILE, json.dumps(document, indent=1) + "\n")
    return document


def evaluate_follower(task: str | Path, *, episodes: int, seed: int = DEFAULT_SEED,
                      num_envs: int = 10, thresholds: dict[str, float] | None = None,
                      avoid_obstacles: bool = False) -> dict[str, Any]:
    """The scripted lane follower through the same episodes and metrics as a run; with
    ``avoid_obstacles`` the training teacher, which swerves around obstacles."""
    env = make_env(task, num_envs=num_envs, observation="state", action="duty", seed=seed)
    try:
        result = run_episodes(env, FollowerPolicy(env, avoid_obstacles=avoid_obstacles),
                              episodes)
    finally:
        env.close()
    objects = env.config.map.objects
    return result_document(
        result, "duty", thresholds=thresholds or {"lane": 0.5, "collision": 0.02},
        settings={"episodes": episodes, "seed": seed, "num_envs": num_envs,
                  "deterministic": True},
        source={"task": str(task), "algo": "teacher" if avoid_obstacles else "follower",
                "action": "duty", "obs": "state"},
        objects=objects)


def record_run(run_dir: str | Path, *, episodes: int, seed: int | None = None,
               deterministic: bool = True, viewer: str = "none") -> Path:
    """Records ``episodes`` evaluation episodes of the run's policy (from the same spawn seed as
    :func:`evaluate_run`) to ``<run_dir>/recordings/eval.rrd``; returns the path.

    Raises:
        crllk.errors.RecordingError: if the file cannot be written (a ConfigError).
    """
    from crllk.record import record_episodes  # rerun is imported only when recording

    config = load_run_config(run_dir)
    env = build_env(config, num_envs=1, seed=config.eval.seed if seed is None else seed)
    path = Path(run_dir) / "recordings" / "eval.rrd"
    try:
        actor, info = load_actor(run_dir, env)
        report = record_episodes(env, actor, episodes, path, deterministic=deterministic,
                                 viewer=viewer, multipliers=info["multipliers"],
                                 recording_id=f"crllk-eval-{Path(run_dir).resolve()}")
    finally:
        env.close()
    for message in report.warnings:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    print(f"recording: {path} ({report.episodes} episodes, {report.steps} steps)", flush=True)
    return path


# ----- several runs ------------------------------------------------------------------------
def aggregate(documents: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean and standard deviation (population, ddof 0) across runs of each metric, with
    the per-run values."""
    out: dict[str, Any] = {"runs": [d["source"].get("run_dir") for d in documents]}
    for metric in METRICS:
        values = [float(d["summary"][metric]) for d in documents]
        out[metric] = {"mean": float(np.mean(values)), "std": float(np.std(values)),
                       "values": values}
    out["satisfied"] = [bool(d["summary"]["satisfied"]) for d in documents]
    return out


def format_summary(document: dict[str, Any]) -> str:
    s, src = document["summary"], document["source"]
    name = src.get("run_dir") or f"{src['algo']} on {src['task']}"
    verdict = "both constraints hold" if s["satisfied"] else "constraints violated"
    text = (f"{name}: {document['evaluation']['episodes']} episodes: J_R {s['J_R']:.2f} m, "
            f"J_clane {s['J_clane']:.3f} dm, J_coll {s['J_coll']:.3f}, "
            f"length {s['episode_length']:.0f}: {verdict}")
    split = document.get("breakdown", {})
    for direction, row in split.get("by_direction", {}).items():
        text += (f"\n  started {direction}: {row['episodes']} episodes, J_clane "
                 f"{row['J_clane']:.3f} dm, J_coll {row['J_coll']:.3f}")
    if split.get("collisions_by_object"):
        text += "\n  ended on: " + ", ".join(f"{obstacle} ×{count}" for obstacle, count
                                            in split["collisions_by_object"].items())
    return text


def format_aggregate(result: dict[str, Any]) -> str:
    def show(metric: str, digits: int) -> str:
        return f"{result[metric]['mean']:.{digits}f} ± {result[metric]['std']:.{digits}f}"

    return (f"{len(result['runs'])} runs: J_R {show('J_R', 2)} m, J_clane {show('J_clane', 3)} "
            f"dm, J_coll {show('J_coll', 3)}")


# ----- command line ------------------------------------------------------------------------
def parse(argv: Sequence[str]) -> EvaluateConfig:
    """``key=value`` arguments checked against :class:`EvaluateConfig`."""
    schema = OmegaConf.structured(EvaluateConfig)
    try:
        merged = OmegaConf.merge(schema, OmegaConf.from_dotlist(list(argv)))
        config: EvaluateConfig = OmegaConf.to_object(merged)  # type: ignore[assignment]
    except OmegaConfBaseException as err:
        key = getattr(err, "full_key", None) or "<arguments>"
        raise ConfigError(SOURCE, str(key), str(err).splitlines()[0]) from None
    if config.viewer not in ("none", "spawn", "serve"):
        raise ConfigError(SOURCE, "viewer", f"must be one of none, spawn, serve, got "
                          f"{config.viewer!r}")
    for key in ("episodes", "num_envs", "threads", "record_episodes"):
        if getattr(config, key) < 1:
            raise ConfigError(SOURCE, key, f"must be >= 1, got {getattr(config, key)}")
    if not config.run_dirs() and not config.follower and not config.teacher:
        raise ConfigError(SOURCE, "run", "give run=<run_dir>, runs=[...], follower=true or "
                          "teacher=true")
    for run_dir in config.run_dirs():
        if not run_dir.is_dir():
            raise ConfigError(SOURCE, "run", f"no such run directory: {run_dir}")
    return config


def main(argv: Sequence[str] | None = None) -> int:
    try:
        config = parse(sys.argv[1:] if argv is None else argv)
        torch.set_num_threads(config.threads)
        documents = []
        for run_dir in config.run_dirs():
            documents.append(evaluate_run(run_dir, episodes=config.episodes,
                                          deterministic=config.deterministic,
                                          seed=config.seed, num_envs=config.num_envs))
            print(format_summary(documents[-1]), flush=True)
            if config.record:
                record_run(run_dir, episodes=config.record_episodes, seed=config.seed,
                           deterministic=config.deterministic, viewer=config.viewer)
        output: dict[str, Any] = {}
        if len(documents) > 1:
            output["aggregate"] = aggregate(documents)
            print(format_aggregate(output["aggregate"]), flush=True)
        thresholds = {"lane": config.lane_threshold, "collision": config.collision_threshold}
        for name in ("follower", "teacher"):
            if getattr(config, name):
                output[name] = evaluate_follower(
                    config.task, episodes=config.episodes, num_envs=config.num_envs,
                    seed=DEFAULT_SEED if config.seed is None else config.seed,
                    thresholds=thresholds, avoid_obstacles=name == "teacher")
                print(format_summary(output[name]), flush=True)
        if config.out:
            output["runs"] = documents
            Path(config.out).parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(config.out, json.dumps(output, indent=1) + "\n")
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
