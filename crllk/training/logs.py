"""The run's CSV logs (``metrics.csv``, ``eval.csv``), their columns, and the console lines."""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDictBase

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.config import TrainConfig
from crllk.errors import ConfigError
from crllk.files import atomic_write_text, open_no_follow, read_csv_rows, writing
from crllk.tasks.constraints import Constraint

DISCRETE_ACTION_NAMES = ("left", "right", "straight")


class CsvLog:
    """A CSV file with a fixed header, one row appended (and flushed) at a time; opened without
    following a link (a symbolic link planted at its path is refused, naming it)."""

    def __init__(self, path: Path, columns: Sequence[str]):
        self.path = path
        self.columns = list(columns)

    def append(self, row: dict[str, Any]) -> None:
        """Appends ``row`` (its line written at once, after the header if the file is new).

        Raises:
            WriteError: naming the file, if it is a symbolic link or cannot be written.
        """
        fd = open_no_follow(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
        with writing(self.path), os.fdopen(fd, "w", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, fieldnames=self.columns)
            if os.fstat(fd).st_size == 0:
                writer.writeheader()
            writer.writerow({k: _format(row.get(k, "")) for k in self.columns})

    def truncate_after(self, iteration: int) -> None:
        """Drops rows of iterations after ``iteration`` (written after the last checkpoint) and
        a last row that a kill cut short (:func:`crllk.files.read_csv_rows`).

        Raises:
            ConfigError: naming the file, if its header is not one this log writes (damaged,
                or another file's), instead of dropping rows it cannot read.
        """
        header, rows = read_csv_rows(self.path)
        if not header:
            return
        unknown = [column for column in header if column not in self.columns]
        if unknown or "iteration" not in header:
            what = f"unknown columns {', '.join(unknown[:4])}" if unknown else "no iteration"
            raise ConfigError(self.path, "<header>", f"not this run's log ({what}): restore "
                              "the file, or remove it to resume without the run's history")
        kept = [r for r in rows if _iteration(r) is not None and _iteration(r) <= iteration]
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=self.columns, lineterminator="\r\n")
        writer.writeheader()
        writer.writerows(kept)
        atomic_write_text(self.path, buffer.getvalue())


def _iteration(row: dict[str, str]) -> int | None:
    try:
        return int(row["iteration"])
    except (KeyError, ValueError):
        return None


def _format(value: Any) -> Any:
    return f"{value:.6g}" if isinstance(value, float) else value


def metric_columns(action: str, constraints: Sequence[Constraint],
                   loss_keys: Sequence[str]) -> list[str]:
    """``metrics.csv``: counters, J_R and each constraint's metric over the episodes from the
    task's own spawns, the same over encounter episodes, each multiplier, the loss terms
    (``loss_keys``), the actions."""
    metrics = [c.metric for c in constraints]
    columns = ["iteration", "frames", "time_s", "frames_per_s", "episodes", "J_R", *metrics,
               "episode_length", "encounter_episodes", *(f"{m}_encounter" for m in metrics),
               *(f"lambda_{c.name}" for c in constraints), *loss_keys]
    if action == "discrete":
        return columns + [f"action_{n}" for n in DISCRETE_ACTION_NAMES]
    return [*columns, "action_velocity_mean", "action_steering_mean", "action_steering_std"]


def eval_columns(constraints: Sequence[Constraint]) -> list[str]:
    """``eval.csv``: ``time_s`` is the wall time of the run when the evaluation began (earlier
    evaluations included); ``evaluation_s`` how long this evaluation took."""
    return ["iteration", "frames", "time_s", "evaluation_s", "episodes", "J_R",
            *(c.metric for c in constraints), "episode_length", "satisfied"]


def action_columns(batch: TensorDictBase, action: str) -> dict[str, float]:
    """The iteration's action histogram (discrete) or action statistics (continuous)."""
    actions = batch["action"]
    if action == "discrete":
        counts = torch.bincount(actions.reshape(-1), minlength=len(DISCRETE_ACTION_NAMES))
        fractions = counts.to(torch.float64) / counts.sum()
        return {f"action_{name}": float(f) for name, f in zip(DISCRETE_ACTION_NAMES, fractions,
                                                              strict=True)}
    flat = actions.reshape(-1, actions.shape[-1]).to(torch.float64)
    return {"action_velocity_mean": float(flat[:, 0].mean()),
            "action_steering_mean": float(flat[:, 1].mean()),
            "action_steering_std": float(flat[:, 1].std())}


def progress_text(row: dict[str, Any], constraints: Sequence[Constraint]) -> str:
    def show(value: float, digits: int) -> str:
        return "-" if math.isnan(value) else f"{value:.{digits}f}"

    metrics = "  ".join(f"{c.metric} {show(row[c.metric], 2)}" for c in constraints)
    multipliers = "/".join(f"{row[f'lambda_{c.name}']:.2f}" for c in constraints)
    return f"J_R {show(row['J_R'], 2)} m  {metrics}  λ {multipliers}"


def print_last_evaluation(path: Path, config: TrainConfig,
                          constraints: Sequence[Constraint]) -> None:
    """One line on the latest evaluation in ``eval.csv``, if there is one."""
    _, rows = read_csv_rows(path)
    if not rows:
        return
    last = rows[-1]
    verdict = ("every constraint holds" if last["satisfied"] == "1"
               else "constraints violated")
    metrics = ", ".join(
        f"{c.metric} {float(last[c.metric]):.3f} {c.unit} "
        f"(≤ {config.algo.constraints[c.name].threshold})" for c in constraints)
    print(f"evaluation at {last['frames']} frames ({last['episodes']} episodes): "
          f"J_R {float(last['J_R']):.2f} m, {metrics}: {verdict}", flush=True)
