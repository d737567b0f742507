"""Figures from run directories: learning curves and action distributions (matplotlib).

Used by ``python -m crllk.experiments figure1`` and by the notebooks.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch
from matplotlib.ticker import FuncFormatter
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from crllk.evaluation.report import episode_cost
from crllk.files import atomic_write
from crllk.protocol import TEST_EVALUATION, TEST_MODE_EVALUATION
from crllk.tasks.actions import DISCRETE_NAMES
from crllk.training.build import build_env
from crllk.training.runs import (
    deployed_forms,
    load_actor,
    load_run_config,
    played_action,
    read_eval_json,
    read_metrics,
)

SMOOTHING_ITERATIONS = 10
"""Window (iterations) of the moving average over training curves."""
CURVES = (("lambda_lane", "λ_lane"), ("J_clane", "J_clane (dm)"), ("J_R", "J_R (m per episode)"))
"""Figure 1's panels: metrics.csv column and axis label."""


THOUSANDS = FuncFormatter(lambda value, _: f"{value / 1000:g}k")
"""Axis labels in thousands (frames)."""


def moving_average(values: np.ndarray, window: int = SMOOTHING_ITERATIONS) -> np.ndarray:
    """Mean of the last ``window`` finite values at each index (NaN until there is one)."""
    out = np.full(len(values), np.nan)
    for i in range(len(values)):
        recent = values[max(0, i - window + 1): i + 1]
        recent = recent[np.isfinite(recent)]
        if recent.size:
            out[i] = recent.mean()
    return out


def seed_band(run_dirs: Sequence[Path], column: str,
              smooth: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Frames and the mean, min and max across runs of a smoothed ``metrics.csv`` column,
    over the frames all runs reached."""
    curves = [read_metrics(d) for d in run_dirs]
    curves = [c for c in curves if c]
    length = min(len(c["frames"]) for c in curves)
    frames = curves[0]["frames"][:length]
    values = np.stack([moving_average(c[column][:length]) if smooth else c[column][:length]
                       for c in curves])
    with warnings.catch_warnings():  # iterations before any episode finished are NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return frames, np.nanmean(values, 0), np.nanmin(values, 0), np.nanmax(values, 0)


def plot_action_distribution(ax: Any, histograms: Mapping[str, Mapping[str, float]]) -> None:
    """Bars of the fraction of each discrete action, one group per label."""
    width = 0.8 / max(len(histograms), 1)
    positions = np.arange(len(DISCRETE_NAMES))
    for k, (label, histogram) in enumerate(histograms.items()):
        total = sum(histogram[name] for name in DISCRETE_NAMES) or 1.0
        fractions = [histogram[name] / total for name in DISCRETE_NAMES]
        ax.bar(positions + (k - (len(histograms) - 1) / 2) * width, fractions, width,
               label=label)
    ax.set_xticks(positions, DISCRETE_NAMES)
    ax.set_ylabel("fraction of steps")
    ax.legend()


def save_figure(figure: Any, path: Path) -> Path:
    """Writes a PNG atomically and closes the figure."""
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda handle: figure.savefig(handle, format="png", dpi=120))
    plt.close(figure)
    return path


@torch.no_grad()
def policy_trajectory(run_dir: str | Path, *, seed: int | None = None,
                      deterministic: bool = False) -> dict[str, Any]:
    """One episode of the run's policy (sampled from a generator seeded with ``seed``, as the
    evaluation plays it, or the deployed policy with ``deterministic``) from spawn ``seed``
    (default: the run's evaluation seed): the top-down picture with the driven trail (PIL
    image), the trail (x, y in m), the per-step actions and lane costs, the distance (m) and
    the termination reason."""
    from crllk.analysis.pictures import topdown

    config = load_run_config(run_dir)
    seed = config.eval.seed if seed is None else seed
    env = build_env(config, num_envs=1, seed=seed, action=played_action(config, deterministic))
    try:
        actor, _ = load_actor(run_dir, env, deployed=deterministic)
        physics, task = env.physics[0], env.tasks[0]
        td = env.reset()
        trail, actions, lane_costs, distance = [physics.pose()[:2]], [], [], 0.0
        exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
        with set_exploration_type(exploration), torch.random.fork_rng():
            torch.manual_seed(seed)
            while True:
                td = env.step(actor(td))
                trail.append(physics.pose()[:2])
                actions.append(td["action"][0].tolist())
                lane_costs.append(float(td["next", "cost_lane"]))
                distance += float(td["next", "reward"])
                if bool(td["next", "done"]):
                    break
                td = step_mdp(td)
        return {"image": topdown(physics, task.map, trail), "trail": np.array(trail),
                "actions": actions, "lane_costs": np.array(lane_costs), "distance": distance,
                "termination": task.outcome.termination or "time_limit"}
    finally:
        env.close()


def figure1_data(by_threshold: Mapping[float, Sequence[Path]],
                 settings: Mapping[str, Any]) -> dict[str, Any]:
    """Everything Figure 1 draws, from the run directories: per lane threshold the learning
    curves (mean and range over seeds of the smoothed training metrics), the action counts of
    one test episode (evaluation episode 0 of the first seed) and the test evaluations of the
    sampled policy and, where made, of the deployed one."""
    data: dict[str, Any] = {"settings": dict(settings), "thresholds": {}}
    for threshold, run_dirs in by_threshold.items():
        curves = {}
        for column, _ in CURVES:
            frames, mean, low, high = seed_band(run_dirs, column)
            curves[column] = {"frames": frames.tolist(), "mean": mean.tolist(),
                              "min": low.tolist(), "max": high.tolist()}
        episode = read_eval_json(run_dirs[0], TEST_EVALUATION)["episodes"][0]
        modes = [read_eval_json(d, TEST_MODE_EVALUATION) for d in run_dirs
                 if (d / f"{TEST_MODE_EVALUATION}.json").is_file()]
        data["thresholds"][f"{threshold:g}"] = {
            "runs": [str(d) for d in run_dirs], "curves": curves,
            "test_episode": {"run_dir": str(run_dirs[0]), "actions": episode["actions"],
                             "J_R": episode["distance"],
                             "J_clane": episode_cost(episode, "lane"),
                             "collisions": episode_cost(episode, "collision")},
            "evaluations": [read_eval_json(d, TEST_EVALUATION)["summary"] for d in run_dirs],
            "mode_evaluations": [m["summary"] for m in modes],
            "deployed": deployed_forms(modes),
            "final_lambda_lane": [float(read_metrics(d)["lambda_lane"][-1]) for d in run_dirs]}
    return data


def draw_figure1_curves(data: Mapping[str, Any]) -> Any:
    """Figure 1's learning curves (λ_lane, J_clane, J_R against frames) per threshold."""
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    figure, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    for k, (threshold, entry) in enumerate(data["thresholds"].items()):
        for ax, (column, title) in zip(axes, CURVES, strict=True):
            curve = entry["curves"][column]
            ax.plot(curve["frames"], curve["mean"], color=colors[k], label=f"α1 = {threshold}")
            ax.fill_between(curve["frames"], curve["min"], curve["max"], color=colors[k],
                            alpha=0.2, linewidth=0)
            ax.set_xlabel("environment frames")
            ax.xaxis.set_major_formatter(THOUSANDS)
            ax.set_ylabel(title)
            if column == "J_clane":
                ax.axhline(float(threshold), color=colors[k], linestyle="--", linewidth=1)
    axes[0].legend()
    settings = data["settings"]
    figure.suptitle(f"CRLLK-D on small_loop from {settings['obs']}: training episodes, "
                    f"{SMOOTHING_ITERATIONS}-iteration average, band = range over seeds "
                    f"{', '.join(map(str, settings['seeds']))}", fontsize=10)
    return figure


def draw_figure1_actions(data: Mapping[str, Any]) -> Any:
    """The action distribution of one test episode per threshold."""
    figure, ax = plt.subplots(figsize=(5.5, 3.4), constrained_layout=True)
    plot_action_distribution(ax, {f"α1 = {t}": e["test_episode"]["actions"]
                                  for t, e in data["thresholds"].items()})
    ax.set_title("one test episode per threshold (evaluation episode 0)", fontsize=10)
    return figure


def draw_figure1_tradeoff(data: Mapping[str, Any], sweep: Mapping[str, Any] | None) -> Any:
    """J_R against J_clane: CRLLK-D for every α1 (each seed a dot, their mean a star, α1 a
    dashed line of the same colour) and, where ``sweep`` (a sweep document of the same
    observation with ``small_loop``) is given, the fixed-weight PPO-D pairs (filled where both
    constraints hold on every seed)."""
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    figure, ax = plt.subplots(figsize=(6.0, 4.2), constrained_layout=True)
    fixed = (sweep or {}).get("maps", {}).get("small_loop", {}).get("fixed", [])
    for e in fixed:
        holds = e["satisfied_all_seeds"]
        ax.scatter([e["J_clane"]["mean"]], [e["J_R"]["mean"]], s=30, color="grey",
                   facecolors="grey" if holds else "none")
        ax.annotate(f"{e['lane_weight']:g}/{e['collision_weight']:g}",
                    (e["J_clane"]["mean"], e["J_R"]["mean"]), fontsize=6, color="grey",
                    xytext=(3, 3), textcoords="offset points")
    for k, (threshold, entry) in enumerate(data["thresholds"].items()):
        color = colors[k % len(colors)]
        lane = [e["J_clane"] for e in entry["evaluations"]]
        travel = [e["J_R"] for e in entry["evaluations"]]
        ax.scatter(lane, travel, s=14, color=color)
        ax.scatter([float(np.mean(lane))], [float(np.mean(travel))], s=150, marker="*",
                   color=color, label=f"CRLLK-D, α1 = {threshold} dm")
        ax.axvline(float(threshold), color=color, linestyle="--", linewidth=1)
    if fixed:
        ax.scatter([], [], s=30, color="grey", label="PPO-D, fixed λ_lane/λ_coll (filled: holds)")
    ax.set_xlabel("J_clane (dm)")
    ax.set_ylabel("J_R (m per episode)")
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("small_loop: the lane constraint against travel", fontsize=10)
    return figure


def figure1_pictures(by_threshold: Mapping[float, Sequence[Path]], results: Path,
                     settings: Mapping[str, Any],
                     sweep: Mapping[str, Any] | None = None) -> list[Path]:
    """Writes ``figure1.json`` (the numbers) and the three PNGs drawn from it (the trade-off
    with the fixed-weight ``sweep``'s ``small_loop`` pairs where given)."""
    data = figure1_data(by_threshold, settings)
    results.mkdir(parents=True, exist_ok=True)
    numbers = results / "figure1.json"
    atomic_write(numbers, lambda handle: handle.write(json.dumps(data, indent=1).encode()))
    return [numbers, save_figure(draw_figure1_curves(data), results / "figure1_curves.png"),
            save_figure(draw_figure1_actions(data), results / "figure1_actions.png"),
            save_figure(draw_figure1_tradeoff(data, sweep), results / "figure1_tradeoff.png")]


__all__ = ["draw_figure1_actions", "draw_figure1_curves", "draw_figure1_tradeoff",
           "figure1_data", "figure1_pictures",
           "moving_average", "plot_action_distribution", "policy_trajectory", "save_figure",
           "seed_band"]


def draw_sweep(document: Mapping[str, Any]) -> Any:
    """One panel per map: J_R against J_clane of every fixed-weight pair (filled where both
    constraints hold on every seed, labelled λ_lane/λ_coll) and of CRLLK-D (a star); the
    dashed line is α1."""
    maps = document["maps"]
    figure, axes = plt.subplots(1, len(maps), figsize=(4.6 * len(maps), 4.0), squeeze=False)
    alpha = document["thresholds"]["lane"]
    for ax, (task, entry) in zip(axes[0], maps.items(), strict=True):
        for e in entry["fixed"]:
            x, y = e["J_clane"]["mean"], e["J_R"]["mean"]
            holds = e["satisfied_all_seeds"]
            ax.scatter([x], [y], s=36, marker="o", color="tab:blue",
                       facecolors="tab:blue" if holds else "none")
            ax.annotate(f"{e['lane_weight']:g}/{e['collision_weight']:g}", (x, y), fontsize=7,
                        xytext=(3, 3), textcoords="offset points")
        c = entry["crllk"]
        ax.scatter([c["J_clane"]["mean"]], [c["J_R"]["mean"]], s=140, marker="*",
                   color="tab:red" if c["satisfied_all_seeds"] else "none",
                   edgecolors="tab:red", label="CRLLK-D (learned λ)")
        ax.axvline(alpha, linestyle="--", color="grey", linewidth=1)
        ax.set_title(f"{task}: {entry['feasible_pairs']} of {len(entry['fixed'])} pairs hold")
        ax.set_xlabel("J_clane (dm)")
        ax.set_ylabel("J_R (m per episode)")
    axes[0][0].scatter([], [], s=36, color="tab:blue", label="PPO-D, both constraints hold")
    axes[0][0].scatter([], [], s=36, facecolors="none", edgecolors="tab:blue",
                       label="PPO-D, a constraint fails (λ_lane/λ_coll)")
    axes[0][0].legend(fontsize=7, loc="lower right")
    figure.tight_layout()
    return figure


def draw_robustness(document: Mapping[str, Any]) -> Any:
    """Per map, J_coll and J_clane (mean, with the seeds' spread) under each condition, for
    the policies trained without and with randomisation; dashed lines are the thresholds."""
    cells = document["cells"]
    tasks = list(dict.fromkeys(c["task"] for c in cells))
    names = list(dict.fromkeys(c["condition"] for c in cells))
    trainings = list(dict.fromkeys(c["training"] for c in cells))
    figure, axes = plt.subplots(len(tasks), 2, figsize=(11, 3.2 * len(tasks)), squeeze=False)
    width = 0.8 / len(trainings)
    for row, task in enumerate(tasks):
        for col, (metric, threshold) in enumerate((("J_coll", "collision"), ("J_clane", "lane"))):
            ax = axes[row][col]
            for k, training in enumerate(trainings):
                entries = [next(c for c in cells if c["task"] == task
                                and c["training"] == training and c["condition"] == name)
                           for name in names]
                positions = np.arange(len(names)) + (k - (len(trainings) - 1) / 2) * width
                ax.bar(positions, [e[metric]["mean"] for e in entries], width,
                       yerr=[e[metric]["std"] for e in entries], label=training, capsize=2)
            ax.axhline(document["thresholds"][threshold], linestyle="--", color="grey",
                       linewidth=1)
            ax.set_xticks(np.arange(len(names)), names, rotation=30, ha="right", fontsize=8)
            ax.set_title(f"{task}: {metric}")
    axes[0][0].legend(fontsize=8)
    figure.tight_layout()
    return figure
