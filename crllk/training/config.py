"""The trainer's configuration: a typed schema over the Hydra config, checked before any work.

The YAML files in ``crllk/conf`` hold the values and their comments; the dataclasses here hold
the types and the ranges. :func:`validate` merges a composed Hydra config into the schema (a
string where a number belongs fails there) and checks every range, raising a
:class:`~crllk.errors.ConfigError` that names the field, e.g.
``override: algo.constraints.lane.threshold: must be >= 0, got -1.0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from crllk.errors import ConfigError

SOURCE = "override"
"""How errors name where a bad value came from (the command line or the YAML defaults)."""


@dataclass
class ConstraintConfig:
    """The multiplier of one constraint (``algo.constraints.<name>``)."""

    threshold: float = 0.0
    initial: float = 0.0
    step_size: float = 0.05
    max_value: float = 100.0
    kp: float = 0.0
    kd: float = 0.0


@dataclass
class AlgoConfig:
    name: str = "crllk"
    multiplier: str = "dual"
    schedule: str = "batch"
    frozen: bool = False
    constraints: dict[str, ConstraintConfig] = field(default_factory=dict)
    """Multiplier settings by constraint name; every constraint of the task needs one."""


@dataclass
class ActionConfig:
    name: str = "discrete"
    baseline_collision_weight: float = 4.0


@dataclass
class ObsConfig:
    name: str = "state"


@dataclass
class PPOConfig:
    gamma: float = 0.95
    gae_lambda: float = 0.95
    clip_epsilon: float = 0.2
    epochs: int = 10
    minibatch_size: int = 512
    lr: float = 1e-3
    anneal_lr: bool = True
    lr_final_fraction: float = 0.0
    max_grad_norm: float = 1.0
    entropy_coeff: float = 0.01
    critic_coeff: float = 0.5
    normalize_advantage: bool = True


@dataclass
class ModelSchema:
    encoder: str = "fast"
    hidden: int = 64
    feature_dim: int = 256
    initial_log_std: float = -0.5
    shared_critic: bool = False
    critic_input: str = "observation"
    policy_commands: bool = False


@dataclass
class TeacherConfig:
    coeff: float = 0.0
    frames: int = 0
    final: float = 0.0


@dataclass
class EvalConfig:
    every: int = 100
    episodes: int = 100
    num_envs: int = 10
    seed: int = 1_000_000


@dataclass
class TrainConfig:
    task: dict[str, Any] = field(default_factory=dict)
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    action: ActionConfig = field(default_factory=ActionConfig)
    obs: ObsConfig = field(default_factory=ObsConfig)
    seed: int = 0
    total_frames: int = 300_000
    run_dir: str | None = None
    resume: bool = False
    task_file: str | None = None
    num_envs: int = 16
    rollout_steps: int = 64
    reward_scale: float = 30.0
    absorbing_off_road: bool = False
    encounters: float = 0.0
    encounter_horizon: int = 0
    threads: int = 1
    checkpoint_every: int = 10
    progress: bool = True
    record_every: int = 0
    viewer: str = "none"
    live: str = "none"
    live_port: int = 9877
    ppo: PPOConfig = field(default_factory=PPOConfig)
    model: ModelSchema = field(default_factory=ModelSchema)
    eval: EvalConfig = field(default_factory=EvalConfig)
    teacher: TeacherConfig = field(default_factory=TeacherConfig)

    @property
    def task_name(self) -> str:
        return str(self.task.get("name", "task"))

    @property
    def frames_per_batch(self) -> int:
        return self.num_envs * self.rollout_steps

    def task_source(self) -> str | Path:
        """What :func:`crllk.tasks.config.load_task_config` reads: the task file or name."""
        return self.task_file if self.task_file else self.task_name

    def task_overrides(self) -> dict[str, Any]:
        """The task settings as composed (command-line changes included), without the map."""
        if self.task_file:
            return {}
        return {k: v for k, v in self.task.items() if k not in ("name", "map")}

    def default_run_dir(self) -> Path:
        stem = Path(self.task_file).stem if self.task_file else self.task_name
        return Path.cwd() / "runs" / stem / (
            f"{self.algo.name}-{self.action.name}-{self.obs.name}-seed{self.seed}")

    def resolved_run_dir(self) -> Path:
        return Path(self.run_dir).expanduser().resolve() if self.run_dir else self.default_run_dir()


_CHOICES = {
    "algo.name": ("crllk", "ppo"),
    "algo.multiplier": ("dual", "pid"),
    "algo.schedule": ("episode", "batch"),
    "action.name": ("discrete", "continuous", "duckietown"),
    "obs.name": ("state", "pixels"),
    "model.encoder": ("fast", "original"),
    "model.critic_input": ("observation", "state"),
    "viewer": ("none", "spawn", "serve"),
    "live": ("none", "serve", "spawn"),
}
_POSITIVE = ("total_frames", "num_envs", "rollout_steps", "threads", "checkpoint_every",
             "ppo.epochs", "ppo.minibatch_size", "ppo.lr", "ppo.max_grad_norm",
             "model.hidden", "model.feature_dim", "eval.episodes", "eval.num_envs",
             "reward_scale")
_NON_NEGATIVE = ("seed", "encounter_horizon", "eval.every", "teacher.coeff", "teacher.frames",
                 "teacher.final", "record_every", "eval.seed", "ppo.entropy_coeff",
                 "ppo.critic_coeff", "action.baseline_collision_weight")
_CONSTRAINT_POSITIVE = ("step_size",)
_CONSTRAINT_NON_NEGATIVE = ("threshold", "initial", "kp", "kd")
_UNIT_INTERVAL = ("ppo.gamma", "ppo.gae_lambda", "ppo.lr_final_fraction", "encounters")
_PORTS = 65536
"""TCP ports are 1 ... 65535."""


def validate(cfg: DictConfig | dict[str, Any]) -> TrainConfig:
    """A typed, range-checked :class:`TrainConfig` from a composed config.

    Raises:
        ConfigError: naming the first field that is missing, of the wrong type or out of range.
    """
    schema = OmegaConf.structured(TrainConfig)
    try:
        merged = OmegaConf.merge(schema, cfg)
        config: TrainConfig = OmegaConf.to_object(merged)  # type: ignore[assignment]
    except OmegaConfBaseException as err:
        key = getattr(err, "full_key", None) or "<config>"
        message = str(err).splitlines()[0]
        raise ConfigError(SOURCE, str(key), message) from None
    for key, choices in _CHOICES.items():
        value = _get(config, key)
        if value not in choices:
            raise ConfigError(SOURCE, key, f"must be one of {', '.join(choices)}, got {value!r}")
    for key in _POSITIVE:
        _check_range(key, _get(config, key), lambda v: v > 0, "must be > 0")
    for key in _NON_NEGATIVE:
        _check_range(key, _get(config, key), lambda v: v >= 0, "must be >= 0")
    for key in _UNIT_INTERVAL:
        _check_range(key, _get(config, key), lambda v: 0 <= v <= 1, "must lie in [0, 1]")
    if not 0 < config.ppo.clip_epsilon < 1:
        raise ConfigError(SOURCE, "ppo.clip_epsilon",
                          f"must lie in (0, 1), got {config.ppo.clip_epsilon}")
    for name, constraint in config.algo.constraints.items():
        where = f"algo.constraints.{name}"
        for key in _CONSTRAINT_POSITIVE:
            _check_range(f"{where}.{key}", getattr(constraint, key), lambda v: v > 0,
                         "must be > 0")
        for key in _CONSTRAINT_NON_NEGATIVE:
            _check_range(f"{where}.{key}", getattr(constraint, key), lambda v: v >= 0,
                         "must be >= 0")
        if constraint.max_value < constraint.initial:
            raise ConfigError(SOURCE, f"{where}.max_value",
                              f"must be >= {where}.initial ({constraint.initial}), "
                              f"got {constraint.max_value}")
    if not 0 < config.live_port < _PORTS:
        raise ConfigError(SOURCE, "live_port", f"must lie in [1, {_PORTS - 1}], got "
                          f"{config.live_port}")
    if config.live != "none" and config.viewer != "none":
        raise ConfigError(SOURCE, "viewer", f"must be none with live={config.live} (the live "
                          f"view already shows the recordings), got {config.viewer!r}")
    if config.task_file and not Path(config.task_file).exists():
        raise ConfigError(SOURCE, "task_file", f"no such file: {config.task_file}")
    return config


def upgrade(stored: DictConfig) -> DictConfig:
    """A run's saved ``config.yaml`` in the current layout: multipliers that an older version
    kept at ``algo.lane`` and ``algo.collision`` move to ``algo.constraints.<name>``."""
    algo = stored.get("algo")
    if algo is not None and "constraints" not in algo:
        moved = {name: algo.pop(name) for name in ("lane", "collision") if name in algo}
        algo["constraints"] = moved
    return stored


def _get(config: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        config = getattr(config, part)
    return config


def _check_range(key: str, value: float, ok: Any, problem: str) -> None:
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(SOURCE, key, f"must be finite, got {value}")
    if not ok(value):
        raise ConfigError(SOURCE, key, f"{problem}, got {value}")


__all__ = ["ConstraintConfig", "TrainConfig", "upgrade", "validate"]
