"""The trainer's settings: every value's default, unit and range, in one place.

Hydra composes ``python -m crllk.train``'s configuration from :class:`TrainConfig` (registered
as the schema ``train_schema``), then the groups in ``crllk/conf`` (``algo``, ``action``,
``obs``: the values that differ between their choices), the task and the command line.
:func:`validate` checks the result field by field (:mod:`crllk.settings`), raising a
:class:`~crllk.errors.ConfigError` that names the field, e.g.
``override: algo.constraints.lane.threshold: must be >= 0, got -1.0``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from crllk.protocol import VALIDATION_EPISODES, VALIDATION_SEED
from crllk.rl.model_config import ModelConfig
from crllk.settings import (
    MAX_EPISODES,
    MAX_SIMULATIONS,
    at_most,
    host_port,
    non_negative,
    one_of,
    open_unit_interval,
    parse,
    positive,
    setting,
    spawn_seed,
    tcp_port,
    unit_interval,
)
from crllk.tasks.actions import POLICY_ACTIONS
from crllk.tasks.follower import FollowerGains

SOURCE = "override"
"""How errors name where a bad value came from (the command line or the configuration)."""
SCHEMA_NAME = "train_schema"
"""The name under which :class:`TrainConfig` is stored in Hydra's ConfigStore."""
CONF_DIR = Path(__file__).resolve().parent / "conf"
CLUSTER_EXTRA = "the cluster extra: pip install -e '.[cluster]'"
"""What installs Ray and the cluster launchers."""


@dataclass
class ConstraintConfig:
    """The multiplier of one constraint (``algo.constraints.<name>``)."""

    threshold: float = setting(check=non_negative)
    """alpha: the most the constraint's metric may be (in the constraint's unit)."""
    target: float | None = None
    """The value dual ascent drives the metric to (None: ``threshold``). A target below alpha
    leaves a margin for the evaluation's sampling noise: a policy trained to sit at alpha
    meets it in about half of its evaluations. Verdicts always compare with ``threshold``."""
    initial: float = setting(0.0, check=non_negative)
    """lambda at the start (with ``algo.frozen``: the fixed weight)."""
    step_size: float = setting(0.05, check=positive)
    """eta: the dual ascent step per update (PID: the integral gain)."""
    max_value: float = setting(100.0, check=non_negative)
    """lambda_max: the projection's upper bound."""
    kp: float = setting(0.0, check=non_negative)
    """PID only (``algo.multiplier=pid``): proportional gain."""
    kd: float = setting(0.0, check=non_negative)
    """PID only: derivative gain."""

    def problems(self) -> Iterator[tuple[str, str]]:
        if self.max_value < self.initial:
            yield "max_value", (f"must be >= initial ({self.initial}), got {self.max_value}")
        if self.target is not None and not 0.0 <= self.target <= self.threshold:
            yield "target", (f"must be between 0 and the threshold ({self.threshold}), got "
                             f"{self.target}")

    def dual_target(self) -> float:
        """What the multiplier's dual ascent compares the metric with."""
        return self.threshold if self.target is None else self.target


DEFAULT_LEARNER = "ppo_lagrangian"
"""The paper's learner (:mod:`crllk.algos.ppo_lagrangian`)."""


@dataclass
class AlgoConfig:
    """The learner (``algo=crllk``: learned multipliers; ``algo=ppo``: fixed weights)."""

    name: str = setting(check=one_of("crllk", "ppo"))
    learner: str = DEFAULT_LEARNER
    """The learning algorithm, a module of :mod:`crllk.algos` (checked when the run is built)."""
    options: dict[str, Any] = field(default_factory=dict)
    """The learner's own settings, checked by its module (``algo.options.<name>``)."""
    multiplier: str = setting("dual", check=one_of("dual", "pid"))
    """dual: projected dual ascent; pid: the PID Lagrangian (Stooke et al. 2020)."""
    schedule: str = setting("batch", check=one_of("episode", "batch"))
    """batch: one multiplier update per iteration on the mean of its finished episodes;
    episode: one update per finished episode."""
    frozen: bool = False
    """The multipliers stay at ``initial``: fixed reward weights."""
    constraints: dict[str, ConstraintConfig] = field(default_factory=dict)
    """Multiplier settings by constraint name; every constraint of the task needs one."""


@dataclass
class ActionConfig:
    """The action space (``action=discrete|continuous|stoppable|duckietown``)."""

    name: str = setting(check=one_of(*POLICY_ACTIONS))
    baseline_collision_weight: float = setting(check=non_negative)
    """The fixed collision weight of the PPO baseline with this action space."""


@dataclass
class ObsConfig:
    """What the policy reads (``obs=pixels|state``)."""

    name: str = setting(check=one_of("state", "pixels"))
    history: int = setting(1, check=positive)
    """Pixels only: camera images the policy reads at once, newest first (1: the current one),
    a memory of obstacles that went out of view."""
    history_stride: int = setting(1, check=positive)
    """Control steps between those images (1/30 s each)."""

    def problems(self) -> Iterator[tuple[str, str]]:
        if self.history > 1 and self.name != "pixels":
            yield "history", f"needs obs=pixels (a history of camera images), got obs={self.name}"


@dataclass
class PPOConfig:
    gamma: float = setting(0.95, check=unit_interval)
    """Discount (as the original)."""
    gae_lambda: float = setting(0.95, check=unit_interval)
    """GAE lambda (as the original)."""
    cost_gamma: float | None = setting(None, check=unit_interval)
    """Discount of the cost critics and the cost advantages (None: ``gamma``). How much a
    cost k control steps ahead counts now: gamma^k, so a collision 60 steps (2 s, a swerve)
    ahead counts 0.95^60 = 0.05 of itself at 0.95 and 0.99^60 = 0.55 at 0.99."""
    clip_epsilon: float = setting(0.2, check=open_unit_interval)
    epochs: int = setting(10, check=positive)
    """Passes over each batch."""
    minibatch_size: int = setting(512, check=positive)
    """Transitions per gradient step."""
    lr: float = setting(1e-3, check=positive)
    """Adam learning rate."""
    anneal_lr: bool = True
    """The learning rate falls linearly over ``total_frames`` (false: constant), so that the
    policy a run ends with is not a noisy last iterate."""
    lr_final_fraction: float = setting(0.0, check=unit_interval)
    """With ``anneal_lr``: the rate falls to ``lr`` x this at the end."""
    max_grad_norm: float = setting(1.0, check=positive)
    """Gradient-norm clip."""
    entropy_coeff: float = setting(0.01, check=non_negative)
    """c_H, the weight of the entropy bonus."""
    entropy_final_fraction: float = setting(1.0, check=unit_interval)
    """The entropy bonus falls linearly over ``total_frames`` to ``entropy_coeff`` x this
    (1: constant), so that the sampled policy can sharpen toward its mode."""
    critic_coeff: float = setting(0.5, check=non_negative)
    normalize_advantage: bool = True
    """Standardise the combined advantage over each minibatch."""

    def discount_of_costs(self) -> float:
        """The cost critics' discount: ``cost_gamma``, else ``gamma``."""
        return self.gamma if self.cost_gamma is None else self.cost_gamma


@dataclass
class TeacherConfig:
    """The privileged teacher (:mod:`crllk.tasks.teacher`: the scripted follower, swerving
    around obstacles)."""

    coeff: float = setting(1.0, check=non_negative)
    """Weight of the imitation term -mean(log pi(a_teacher | s)) at the start (0: no teacher)."""
    frames: int = setting(150_000, check=non_negative)
    """The weight moves linearly to ``final`` over these frames ..."""
    final: float = setting(0.3, check=non_negative)
    """... and stays there (0: Lagrangian PPO alone after ``frames``)."""
    margin: float = setting(FollowerGains.avoid_margin, check=non_negative)
    """Gap (m) the teacher keeps between the robot's side and an obstacle's edge while passing
    it (only maps with obstacles in a lane are affected)."""


@dataclass
class EvalConfig:
    """The evaluations written to ``eval.csv`` during training."""

    every: int = setting(0, check=non_negative)
    """Iterations between periodic evaluations, for learning curves in ``eval.csv`` (0: none;
    from pixels each costs about 2 min of a 28 min run)."""
    final: bool = True
    """An evaluation at the end of training: the last row of ``eval.csv``, and the run's
    ``eval.json`` from ``python -m crllk.train``."""
    episodes: int = setting(VALIDATION_EPISODES, check=at_most(MAX_EPISODES))
    """Episodes of the sampled policy each time: the same as ``python -m crllk.evaluate``."""
    num_envs: int = setting(10, check=at_most(MAX_SIMULATIONS))
    """Episode k runs in simulation k mod num_envs, as ``crllk.evaluate``'s default."""
    seed: int = setting(VALIDATION_SEED, check=spawn_seed)
    """Spawn seed of the evaluation environment: a validation seed, apart from the training
    seeds (the test seed is refused: :mod:`crllk.protocol`)."""


@dataclass
class TrainConfig:
    """Everything ``python -m crllk.train`` reads; ``key=value`` on its command line."""

    task: dict[str, Any] = field(default_factory=dict)
    """The task's settings (``tasks/<name>.yaml``); ``task.horizon=256`` changes one."""
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    action: ActionConfig = field(default_factory=ActionConfig)
    obs: ObsConfig = field(default_factory=ObsConfig)
    seed: int = setting(0, check=spawn_seed)
    total_frames: int = setting(500_000, check=positive)
    """Environment steps (summed over sub-environments) to train for (``obs=state``: 300,000)."""
    run_dir: str | None = None
    """Default: ``runs/<task>/<algo>-<action>-<obs>-seed<seed>`` under the current directory."""
    resume: bool = False
    """Continue the run in ``run_dir`` from its last checkpoint."""
    task_file: str | None = None
    """Path of a task or Duckietown map file; used instead of ``task=`` when set."""
    num_envs: int = setting(16, check=at_most(MAX_SIMULATIONS))
    """Simulations stepped together (split evenly among ``workers`` processes)."""
    workers: int = setting(1, check=positive)
    """Processes that collect from the simulations (obs=pixels and obs=state: 2); num_envs is
    split among them (num_envs/workers each). Each worker steps its simulations with its own
    copy of the policy, sent once per iteration; the PPO update, evaluations and checkpoints
    stay in the main process. Simulation i spawns from the same seed and samples its actions
    from its own stream whatever the number of workers, so a run with several workers
    collects exactly what it would with one, and resumes exactly from its checkpoints (with
    any number of workers). With collect_ahead, workers=1 is one worker process too. With
    collector=ray: the remote collectors."""
    collect_ahead: bool = False
    """The workers collect the next batch while this process updates the networks on the one
    before (:mod:`crllk.training.batches`), with the policy as it was before that update: each
    batch is one update older than the policy that learns from it (PPO's ratios use the
    probabilities stored with each action, so they stay exact). Needs collector=local; with
    workers=1 the simulations go to one worker process. It changes what is learned, so runs
    with and without it differ."""
    collector: str = setting("local", check=one_of("local", "ray"))
    """Where the simulations run. local: on this machine (workers processes). ray: in workers
    remote collectors of TorchRL's RayCollector (the cluster extra), num_envs/workers
    simulations each, on the Ray cluster at ray_address; each runs a copy of the policy, which
    gets the current weights before every iteration, while the PPO update, evaluations,
    recordings and checkpoints stay in this process. Resume is not exact with ray: the
    simulators' state lives on the collectors and is not checkpointed, so a resumed run keeps
    its networks, optimiser, multipliers and counters but starts fresh episodes (the episodes
    running at the checkpoint are never counted); collector may change on resume."""
    ray_address: str | None = setting(None, check=host_port)
    """collector=ray: host:port of the head of the Ray cluster to join (RAY_AUTH_MODE=token
    when its head was started by ray start); unset: a private Ray instance of this run,
    listening on 127.0.0.1 only."""
    rollout_steps: int = setting(64, check=positive)
    """Control steps per sub-environment per iteration."""
    reward_scale: float = setting(30.0, check=positive)
    """Trained reward = forward progress (m) x this; 30 (the control rate) makes it m/s."""
    absorbing_off_road: bool = False
    """A terminated episode keeps its off-road lane cost for ever
    (:func:`crllk.training.updates.shape_signals`); slower to learn here."""
    encounters: float = setting(0.5, check=unit_interval)
    """Share of training episodes that start 0.3-1.2 m before an obstacle blocking their lane
    (maps with such obstacles; multipliers and J_* in metrics.csv use the other episodes)."""
    encounter_horizon: int = setting(0, check=non_negative)
    """Steps after which such episodes are truncated (0: the task's horizon)."""
    encounter_curve_weight: float = setting(1.0, check=positive)
    """How much likelier such an episode starts before an obstacle on a lane that turns than
    before one on a straight lane (1: the task's own ``spawn.encounter_curve_weight``, by
    default every blocking obstacle alike). ``action=discrete`` sets 4
    (``crllk/conf/action/discrete.yaml``, chosen in ``docs/findings.md``); the Gaussian
    actions keep 1."""
    threads: int = setting(1, check=positive)
    """Torch CPU threads for the networks (the simulations use one core)."""
    checkpoint_every: int = setting(10, check=positive)
    """Iterations between checkpoints (and always at the end)."""
    progress: bool = True
    """A tqdm progress bar on stderr."""
    record_every: int = setting(0, check=non_negative)
    """Iterations between rerun recordings of one evaluation episode (0: off)."""
    viewer: str = setting("none", check=one_of("none", "spawn", "serve"))
    """Recordings also stream live: none | spawn (a local viewer) | serve (on 127.0.0.1)."""
    live: str = setting("none", check=one_of("none", "serve", "spawn"))
    """One live view of the whole run (metrics per iteration and the recordings): none |
    serve (on 127.0.0.1:live_port) | spawn (serve and start a viewer)."""
    live_port: int = setting(9877, check=tcp_port)
    """Port of the live view's server; connect a viewer with
    ``rerun --bind 127.0.0.1 --connect rerun+http://127.0.0.1:9877/proxy``."""
    ppo: PPOConfig = field(default_factory=PPOConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    teacher: TeacherConfig = field(default_factory=TeacherConfig)

    def problems(self) -> Iterator[tuple[str, str]]:
        if self.live != "none" and self.viewer != "none":
            yield "viewer", (f"must be none with live={self.live} (the live view already shows "
                             f"the recordings), got {self.viewer!r}")
        if self.ray_address is not None and self.collector != "ray":
            yield "ray_address", f"is only used with collector=ray, got collector={self.collector}"
        if self.num_envs % self.workers:
            yield "workers", (f"must divide num_envs ({self.num_envs}) into equal shares, "
                              f"got {self.workers} (obs=pixels and obs=state set 2; workers=1 "
                              "steps them in this process, without collect_ahead)")
        if self.collect_ahead and self.collector != "local":
            yield "collect_ahead", ("needs the simulations in worker processes of this machine "
                                    f"(collector=local), got collector={self.collector}")
        if self.task_file and not Path(self.task_file).exists():
            yield "task_file", f"no such file: {self.task_file}"

    @property
    def task_name(self) -> str:
        """The task's name: a task or map file's stem, else the composed ``task.name``."""
        if self.task_file:
            return Path(self.task_file).stem
        return str(self.task.get("name", "task"))

    @property
    def frames_per_batch(self) -> int:
        return self.num_envs * self.rollout_steps

    def task_source(self) -> str | Path:
        """What :func:`crllk.tasks.config.load_task_config` reads: the task file or name."""
        return self.task_file if self.task_file else str(self.task.get("name", "task"))

    def task_overrides(self) -> dict[str, Any]:
        """The task settings as composed (command-line changes included), without the map."""
        if self.task_file:
            return {}
        return {k: v for k, v in self.task.items() if k not in ("name", "map")}

    def default_run_dir(self) -> Path:
        """``runs/<task>/<algo>[-<learner>]-<action>-<obs>-seed<seed>``: the learner is named
        when it is not the default, so runs of two learners never share a folder."""
        learner = "" if self.algo.learner == DEFAULT_LEARNER else f"-{self.algo.learner}"
        return Path.cwd() / "runs" / self.task_name / (
            f"{self.algo.name}{learner}-{self.action.name}-{self.obs.name}-seed{self.seed}")

    def resolved_run_dir(self) -> Path:
        return Path(self.run_dir).expanduser().resolve() if self.run_dir else self.default_run_dir()


def register_schema(store: ConfigStore) -> None:
    """Stores :class:`TrainConfig` as ``train_schema``, the first entry of ``train.yaml``."""
    store.store(name=SCHEMA_NAME, node=TrainConfig)


def validate(cfg: DictConfig | dict[str, Any], source: str | Path = SOURCE) -> TrainConfig:
    """A typed, range-checked :class:`TrainConfig` from a composed config (``source``: where it
    came from, for the messages: the command line's overrides, or a run's ``config.yaml``).

    Raises:
        ConfigError: naming the first field that is missing, of the wrong type or out of range.
    """
    if isinstance(cfg, DictConfig):  # plain values: a learner's options are checked by its
        cfg = OmegaConf.to_container(cfg)  # own module (crllk.algos)
    return parse(TrainConfig, cfg, str(source))


def algo_thresholds(name: str = "crllk") -> dict[str, float]:
    """The constraint thresholds of ``algo=<name>`` (``crllk``: the paper's alpha_1, alpha_2
    and the crossing constraint's), read from its group file."""
    group = OmegaConf.load(CONF_DIR / "algo" / f"{name}.yaml")
    return {key: float(value["threshold"]) for key, value in group["constraints"].items()}


__all__ = ["CLUSTER_EXTRA", "ConstraintConfig", "TrainConfig", "algo_thresholds",
           "register_schema", "validate"]
