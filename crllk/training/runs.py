"""Reading a training run directory: its configuration, checkpoint, logs and evaluation.

A run directory (``python -m crllk.train``) holds ``config.yaml``, ``metrics.csv`` (one row per
iteration), ``eval.csv`` (one row per periodic evaluation), ``checkpoints/last.pt`` and, once
``python -m crllk.evaluate`` has run, ``eval.json``. With every checkpoint the trainer also
writes ``policy.pt``, the policy alone (:func:`crllk.training.checkpoints.policy_state`): a run
kept without its checkpoints (as ``results/runs`` keeps them) can still be evaluated and
exported.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from crllk.config import TrainConfig, validate
from crllk.errors import ConfigError
from crllk.files import read_csv_rows
from crllk.saved_config import read_run_config
from crllk.training.checkpoints import (
    POLICY_FILE,
    load_checkpoint,
    policy_info,
    policy_state,
    save_checkpoint,
)
from crllk.training.run_dir import EVAL_FILE, check_run_folders

CONFIG_FILE = "config.yaml"
CHECKPOINT_FILE = Path("checkpoints") / "last.pt"


def load_run_config(run_dir: str | Path) -> TrainConfig:
    """The validated training configuration saved in ``run_dir``.

    Raises:
        ConfigError: if ``run_dir`` is not a run directory or its config is unusable.
    """
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise ConfigError(run_dir, "run", f"not a run directory (no {CONFIG_FILE})")
    check_run_folders(Path(run_dir))
    stored = read_run_config(path)
    stored["run_dir"] = str(run_dir)
    return validate(stored, source=path)


def has_policy(run_dir: str | Path) -> bool:
    """Whether the run has a policy to act with: a checkpoint or its kept ``policy.pt``."""
    return (Path(run_dir) / CHECKPOINT_FILE).is_file() or (Path(run_dir) / POLICY_FILE).is_file()


def load_run_policy(run_dir: str | Path) -> dict[str, Any]:
    """The run's last policy (:data:`crllk.training.checkpoints.POLICY_KEYS`): from its last
    checkpoint, or where that is gone from its kept ``policy.pt``.

    Raises:
        ConfigError: if the run has neither.
    """
    run_dir = Path(run_dir)
    if (run_dir / CHECKPOINT_FILE).is_file():
        return policy_state(load_checkpoint(run_dir / CHECKPOINT_FILE))
    if (run_dir / POLICY_FILE).is_file():
        return load_checkpoint(run_dir / POLICY_FILE)
    raise ConfigError(run_dir, "run", f"no trained policy yet (neither {CHECKPOINT_FILE} nor "
                      f"{POLICY_FILE})")


def keep_policy(run_dir: str | Path) -> Path | None:
    """Writes ``policy.pt`` from the run's last checkpoint when it is missing or older (runs
    trained before the trainer wrote it); returns its path, or None without a checkpoint."""
    run_dir = Path(run_dir)
    checkpoint, kept = run_dir / CHECKPOINT_FILE, run_dir / POLICY_FILE
    if not checkpoint.is_file():
        return None
    if kept.is_file() and kept.stat().st_mtime >= checkpoint.stat().st_mtime:
        return kept
    return save_checkpoint(kept, policy_state(load_checkpoint(checkpoint)))


EXPECTED_DUTY = "expected_duty"
"""How a discrete run's deployed policy acts (:mod:`crllk.rl.expected_duty`)."""
EXPECTED_ACTION = "expected_action"
"""How a Gaussian run's deployed policy acts: the mean of its squashed actions
(:mod:`crllk.rl.expected_action`)."""
MODE = "mode"
"""How deployed policies acted before: a discrete run's most probable action, a Gaussian
run's tanh of its mean (TorchRL's deterministic action). Evaluations that do not say how their
deployed policy acted played it."""


def deployed_form(action: str) -> str:
    """How the deterministic (deployed) policy of a run with ``action`` acts:
    :data:`EXPECTED_DUTY` for discrete runs, :data:`EXPECTED_ACTION` for the others."""
    return EXPECTED_DUTY if action == "discrete" else EXPECTED_ACTION


def deployed_forms(documents: Sequence[Mapping[str, Any]]) -> list[str]:
    """How the deployed policies of these evaluation documents acted (:func:`deployed_form`;
    :data:`MODE` for documents written before evaluations recorded it, when every deployed
    policy was its mode)."""
    return sorted({d.get("evaluation", {}).get("deployed", MODE) for d in documents})


def played_action(config: TrainConfig, deterministic: bool) -> str:
    """The action type the run's policy plays in: a discrete run's deployed (``deterministic``)
    policy drives its expected wheel duties (``duty``); otherwise the run's own."""
    return "duty" if deterministic and config.action.name == "discrete" else config.action.name


def load_actor(run_dir: str | Path, env: Any,
               deployed: bool = False) -> tuple[torch.nn.Module, dict[str, Any]]:
    """The run's policy (:func:`load_run_policy`) built for ``env``, and its counters
    (``iteration``, ``frames``, ``elapsed``) and multipliers. With ``deployed`` it is the
    deployed policy (:func:`deployed_form`): a Gaussian run's expected action
    (:func:`crllk.rl.expected_action.expected_action_policy`), a discrete run's expected wheel
    duties (:func:`crllk.rl.expected_duty.expected_duty_policy`), which is also what a discrete
    run plays in an environment of ``duty`` actions (:func:`played_action`)."""
    from crllk.algos import build_learner
    from crllk.rl.expected_action import expected_action_policy
    from crllk.rl.expected_duty import expected_duty_policy

    config = load_run_config(run_dir)
    state = load_run_policy(run_dir)
    actor = build_learner(config, env).actor
    actor.load_state_dict(state["actor"])
    actor.eval()
    if config.action.name == "discrete" and (deployed or env.action_type == "duty"):
        if env.action_type != "duty":
            raise ValueError("a discrete run's deployed policy plays in an environment of duty "
                             "actions (played_action)")
        return expected_duty_policy(actor).eval(), policy_info(state)
    if deployed:
        return expected_action_policy(actor).eval(), policy_info(state)
    return actor, policy_info(state)


def read_csv(path: str | Path) -> dict[str, np.ndarray]:
    """A CSV log as columns of floats (empty cells and ``nan`` become NaN); ``{}`` if the
    file does not exist. A last row cut short by a kill is left out
    (:func:`crllk.files.read_csv_rows`)."""
    header, rows = read_csv_rows(path)
    if not rows:
        return {}
    return {key: np.array([_number(row[key]) for row in rows]) for key in header}


def read_metrics(run_dir: str | Path) -> dict[str, np.ndarray]:
    """``metrics.csv``: one entry per training iteration."""
    return read_csv(Path(run_dir) / "metrics.csv")


def read_evaluations(run_dir: str | Path) -> dict[str, np.ndarray]:
    """``eval.csv``: one entry per periodic deterministic evaluation during training."""
    return read_csv(Path(run_dir) / "eval.csv")


def read_eval_json(run_dir: str | Path, name: str | None = None) -> dict[str, Any]:
    """``eval.json`` as written by ``python -m crllk.evaluate`` (or ``<name>.json``, e.g. the
    test evaluation ``test.json``)."""
    return json.loads((Path(run_dir) / (EVAL_FILE if name is None else f"{name}.json"))
                      .read_text())


def _number(text: str | None) -> float:
    try:
        return float(text) if text not in (None, "") else math.nan
    except ValueError:
        return math.nan


__all__ = ["CHECKPOINT_FILE", "CONFIG_FILE", "EVAL_FILE", "POLICY_FILE", "has_policy",
           "keep_policy", "load_actor", "load_run_config",
           "load_run_policy", "read_csv", "read_eval_json", "read_evaluations", "read_metrics"]
