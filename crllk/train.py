"""``python -m crllk.train task=<name>``: Lagrangian PPO (CRLLK) or fixed-weight PPO on a task.

One iteration of the main loop (:func:`train`):

1. collect ``rollout_steps`` control steps in each of ``num_envs`` simulations;
2. update the multipliers λ from the episodes that finished (dual ascent, DESIGN.md §5);
3. compute GAE advantages for the reward and each cost, and run PPO epochs on the combined
   advantage (A_r − Σλ_i A_ci) / (1 + Σλ_i);
4. append a row to ``metrics.csv``; every ``checkpoint_every`` iterations (and at the end)
   write ``checkpoints/last.pt`` atomically; every ``eval.every`` iterations append a
   evaluation to ``eval.csv`` (the same episodes as ``python -m crllk.evaluate``); every
   ``record_every`` iterations record one evaluation episode with rerun; with ``live`` send
   the row and the recordings to the run's live view (:mod:`crllk.live`).

The checkpoint holds the networks, the optimiser, the multipliers, the counters, the random
generators, the simulations' full state and the running episode sums, so ``resume=true``
continues exactly where the uninterrupted run would have been.
"""

from __future__ import annotations

import csv
import fcntl
import io
import math
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import hydra
import torch
from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type
from tqdm import tqdm

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.checkpoint import atomic_write_text, load_checkpoint, save_checkpoint
from crllk.envs import BatchedLaneKeepingEnv, make_env
from crllk.episodes import EpisodeAccumulator, EpisodeStats, summarise
from crllk.errors import ConfigError
from crllk.evaluation import run_episodes
from crllk.lagrange import Multiplier, make_multiplier
from crllk.lane_keeping import state_feature_names
from crllk.loss import AdvantageModules, LagrangianPPOLoss, make_advantage_modules
from crllk.maps import read_yaml
from crllk.models import ModelConfig, make_actor, make_critic, make_shared_critic
from crllk.paths import task_file, task_names
from crllk.train_config import TrainConfig, validate

if TYPE_CHECKING:
    from crllk.live import LiveView

COSTS = ("lane", "collision")
"""Constraint names; cost ``c`` is read from ``("next", "cost_<c>")``."""
DISCRETE_ACTION_NAMES = ("left", "right", "straight")
RESUME_KEEPS = ("total_frames", "progress", "threads", "checkpoint_every", "record_every",
                "viewer", "live", "live_port")
"""Settings a resumed run takes from the command line; all others come from its config.yaml."""
SOURCE_RUN = "run"
"""How errors about the run directory name their source."""
LOSS_KEYS = ("loss_objective", "loss_critic", "loss_cost_critic", "loss_entropy",
             "loss_imitation", "entropy",
             "kl_approx", "clip_fraction", "explained_variance", "explained_variance_lane",
             "explained_variance_collision")


# ----- building the parts ------------------------------------------------------------------
@dataclass
class Learner:
    """The networks, the loss and the optimiser of one run."""

    actor: torch.nn.Module
    critics: dict[str, torch.nn.Module]  # "reward" and one per cost
    loss: LagrangianPPOLoss
    advantages: AdvantageModules
    optimizer: torch.optim.Optimizer


def build_env(config: TrainConfig, *, num_envs: int, seed: int,
              training: bool = False) -> BatchedLaneKeepingEnv:
    """The run's environment; the ``training`` one starts ``encounters`` of its episodes in
    front of an obstacle, the others keep the task's own spawns."""
    overrides = config.task_overrides()
    if training and config.encounters > 0:
        spawn = {**overrides.get("spawn", {}), "encounters": config.encounters}
        if config.encounter_horizon:
            spawn["encounter_horizon"] = config.encounter_horizon
        overrides = {**overrides, "spawn": spawn}
    return make_env(config.task_source(), num_envs=num_envs, observation=config.obs.name,
                    action=config.action.name, seed=seed, overrides=overrides,
                    privileged_state=config.model.critic_input == "state",
                    teacher=training and (config.teacher.coeff > 0 or config.teacher.final > 0),
                    commands=config.model.policy_commands)


def build_learner(config: TrainConfig, env: BatchedLaneKeepingEnv) -> Learner:
    obs = config.obs.name
    shape = env.observation_spec[obs].shape[1:]
    model = ModelConfig(**vars(config.model))
    names = state_feature_names(env.config)
    commands_dim = env.observation_spec["commands"].shape[-1] if model.policy_commands else 0
    actor = make_actor(obs, shape, config.action.name, env.action_spec, model,
                       names if obs == "state" else None, commands_dim=commands_dim)
    value_keys = {"reward": "state_value", **{c: f"state_value_{c}" for c in COSTS}}
    critic_obs = "state" if model.critic_input == "state" else obs
    critic_shape = env.observation_spec[critic_obs].shape[1:]
    critic_names = names if critic_obs == "state" else None
    if model.shared_critic:
        shared = make_shared_critic(critic_obs, critic_shape, model, list(value_keys.values()),
                                    critic_names)
        critics = dict.fromkeys(value_keys, shared)
    else:
        critics = {name: make_critic(critic_obs, critic_shape, model, out_key=key,
                                     feature_names=critic_names)
                   for name, key in value_keys.items()}
    ppo = config.ppo
    loss = LagrangianPPOLoss(actor, critics["reward"], {c: critics[c] for c in COSTS},
                             clip_epsilon=ppo.clip_epsilon, entropy_coeff=ppo.entropy_coeff,
                             critic_coeff=ppo.critic_coeff,
                             normalize_advantage=ppo.normalize_advantage)
    advantages = make_advantage_modules(ppo.gamma, ppo.gae_lambda, critics["reward"],
                                        {c: critics[c] for c in COSTS}, keys=loss.tensor_keys)
    optimizer = torch.optim.Adam(loss.parameters(), lr=ppo.lr)
    return Learner(actor, critics, loss, advantages, optimizer)


def build_multipliers(config: TrainConfig) -> dict[str, Multiplier]:
    algo = config.algo
    multipliers = {}
    for name in COSTS:
        c = getattr(algo, name)
        common = {"threshold": c.threshold, "initial": c.initial, "max_value": c.max_value,
                  "schedule": algo.schedule, "frozen": algo.frozen}
        if algo.multiplier == "pid":
            multipliers[name] = make_multiplier("pid", kp=c.kp, ki=c.step_size, kd=c.kd, **common)
        else:
            multipliers[name] = make_multiplier("dual", step_size=c.step_size, **common)
    return multipliers


def build_run(config: TrainConfig) -> tuple[BatchedLaneKeepingEnv, Learner,
                                            dict[str, Multiplier], torch.Generator]:
    """Seeds torch and builds the environment, the learner, the multipliers and the generator
    of minibatch orders, in this order (a resumed run rebuilds them the same way)."""
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    env = build_env(config, num_envs=config.num_envs, seed=config.seed, training=True)
    return env, build_learner(config, env), build_multipliers(config), generator


# ----- one iteration -----------------------------------------------------------------------
@torch.no_grad()
def collect(env: BatchedLaneKeepingEnv, actor: torch.nn.Module, carry: TensorDictBase,
            steps: int) -> tuple[TensorDictBase, TensorDictBase]:
    """``steps`` control steps of every sub-environment with the stochastic policy; returns
    the transitions ``[N, steps]`` and the tensordict to continue from."""
    transitions = []
    with set_exploration_type(ExplorationType.RANDOM):
        for _ in range(steps):
            actor(carry)
            stepped, carry = env.step_and_maybe_reset(carry)
            transitions.append(stepped)
    return torch.stack(transitions, dim=1), carry


def shape_signals(batch: TensorDictBase, config: TrainConfig, off_road_lane_cost: float) -> None:
    """The signals the learner sees, in place: the reward scaled by ``reward_scale``, and, with
    ``absorbing_off_road``, the lane cost of every later step of a terminated episode folded
    into its last step: the robot stays off the road at ``off_road_lane_cost`` (dm) per step
    for ever, γ·c_off / (1 − γ) in discounted sum. Otherwise ending an episode early would cut
    its lane cost short and a large λ_lane would make leaving the road look cheap."""
    nxt = batch["next"]
    nxt["reward"] = nxt["reward"] * config.reward_scale
    if config.absorbing_off_road:
        gamma = config.ppo.gamma
        tail = off_road_lane_cost * gamma / (1.0 - gamma) if gamma < 1.0 else 0.0
        nxt["cost_lane"] = nxt["cost_lane"] + tail * nxt["terminated"].to(torch.float32)


def ppo_update(learner: Learner, batch: TensorDictBase, config: TrainConfig,
               generator: torch.Generator) -> dict[str, float]:
    """GAE for every signal, then ``epochs`` passes of minibatch PPO; mean diagnostics."""
    learner.advantages(batch)
    flat = batch.reshape(-1)
    size, sums, count = flat.shape[0], dict.fromkeys(LOSS_KEYS, 0.0), 0
    # clip each network's gradient on its own, so large value errors do not shrink the policy's
    networks = {id(n): n for n in (learner.actor, *learner.critics.values())}  # step
    groups = [list(network.parameters()) for network in networks.values()]
    for _ in range(config.ppo.epochs):
        order = torch.randperm(size, generator=generator)
        for start in range(0, size, config.ppo.minibatch_size):
            out = learner.loss(flat[order[start:start + config.ppo.minibatch_size]])
            total = out["loss_objective"] + out["loss_critic"] + out["loss_cost_critic"] + \
                out["loss_entropy"] + out["loss_imitation"]
            learner.optimizer.zero_grad(set_to_none=True)
            total.backward()
            for group in groups:
                torch.nn.utils.clip_grad_norm_(group, config.ppo.max_grad_norm)
            learner.optimizer.step()
            for key in LOSS_KEYS:
                sums[key] += out[key].item()
            count += 1
    return {key: value / count for key, value in sums.items()}


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


def imitation_coeff(config: TrainConfig, frames: int) -> float:
    """Weight of the imitation term after ``frames``: ``teacher.coeff`` at first, linearly
    to ``teacher.final`` at ``teacher.frames``, then ``teacher.final``."""
    teacher = config.teacher
    if teacher.frames == 0:
        return teacher.final
    fraction = min(frames / teacher.frames, 1.0)
    return teacher.coeff + fraction * (teacher.final - teacher.coeff)


def learning_rate(config: TrainConfig, frames: int) -> float:
    """Adam's learning rate after ``frames``: ``ppo.lr``, or with ``ppo.anneal_lr`` falling
    linearly from it to ``ppo.lr × ppo.lr_final_fraction`` at ``total_frames``."""
    ppo = config.ppo
    if not ppo.anneal_lr:
        return ppo.lr
    fraction = min(frames / config.total_frames, 1.0)
    return ppo.lr * (1.0 - fraction * (1.0 - ppo.lr_final_fraction))


def update_multipliers(multipliers: dict[str, Multiplier],
                       episodes: Sequence[EpisodeStats]) -> None:
    """Dual ascent from the finished episodes of the task's own spawn distribution (episodes
    started in front of an obstacle are left out): Ĵ_clane is an episode's mean lane cost
    (dm), Ĵ_coll its number of collisions."""
    episodes = [e for e in episodes if not e.encounter]
    multipliers["lane"].update([e.lane_cost for e in episodes])
    multipliers["collision"].update([e.collisions for e in episodes])


# ----- run directory -----------------------------------------------------------------------
class CsvLog:
    """A CSV file with a fixed header, one row appended (and flushed) at a time."""

    def __init__(self, path: Path, columns: Sequence[str]):
        self.path = path
        self.columns = list(columns)

    def append(self, row: dict[str, Any]) -> None:
        new = not self.path.exists()
        with self.path.open("a", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=self.columns)
            if new:
                writer.writeheader()
            writer.writerow({k: _format(row.get(k, "")) for k in self.columns})

    def truncate_after(self, iteration: int) -> None:
        """Drops rows of iterations after ``iteration`` (written after the last checkpoint)."""
        if not self.path.exists():
            return
        with self.path.open(newline="") as handle:
            rows = [r for r in csv.DictReader(handle) if int(r["iteration"]) <= iteration]
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=self.columns, lineterminator="\r\n")
        writer.writeheader()
        writer.writerows(rows)
        atomic_write_text(self.path, buffer.getvalue())


def _format(value: Any) -> Any:
    return f"{value:.6g}" if isinstance(value, float) else value


def metric_columns(action: str) -> list[str]:
    columns = ["iteration", "frames", "time_s", "frames_per_s", "episodes", "J_R", "J_clane",
               "J_coll", "episode_length", "encounter_episodes", "J_coll_encounter",
               "lambda_lane", "lambda_collision", *LOSS_KEYS]
    if action == "discrete":
        return columns + [f"action_{n}" for n in DISCRETE_ACTION_NAMES]
    return [*columns, "action_velocity_mean", "action_steering_mean", "action_steering_std"]


EVAL_COLUMNS = ["iteration", "frames", "time_s", "evaluation_s", "episodes", "J_R", "J_clane",
                "J_coll", "episode_length", "satisfied"]
"""``time_s``: wall time of the run when the evaluation began (earlier evaluations included);
``evaluation_s``: how long this evaluation took."""


# ----- the main loop -----------------------------------------------------------------------
def train(config: TrainConfig) -> Path:
    """Trains (or resumes) one run; returns its directory."""
    run_dir = config.resolved_run_dir()
    checkpoint_path = run_dir / "checkpoints" / "last.pt"
    resuming = config.resume and checkpoint_path.exists()
    if not resuming and (run_dir / "metrics.csv").exists():
        if not config.resume:
            raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir} already holds a run; pass "
                              "resume=true to continue it or choose another run_dir")
        for stale in ("metrics.csv", "eval.csv"):  # killed before its first checkpoint
            (run_dir / stale).unlink(missing_ok=True)
    env, learner, multipliers, generator = build_run(config)
    lock = lock_run_dir(run_dir)
    episodes = EpisodeAccumulator(config.num_envs)
    metrics = CsvLog(run_dir / "metrics.csv", metric_columns(config.action.name))
    evaluations = CsvLog(run_dir / "eval.csv", EVAL_COLUMNS)
    eval_env = record_env = None
    iteration, frames, elapsed = 0, 0, 0.0

    if resuming:
        state = load_checkpoint(checkpoint_path)
        restore(state, learner, multipliers, episodes, env, generator)
        carry = state["carry"]
        iteration, frames, elapsed = state["iteration"], state["frames"], state["elapsed"]
        metrics.truncate_after(iteration)
        evaluations.truncate_after(iteration)
        print(f"resuming {run_dir} at iteration {iteration}, {frames} frames", flush=True)
    else:
        run_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(run_dir / "config.yaml", OmegaConf.to_yaml(OmegaConf.structured(config)))
        carry = env.reset()
        print(f"run directory: {run_dir}", flush=True)
    live = open_live_view(config, run_dir)

    bar = tqdm(total=config.total_frames, initial=frames, unit="frame", dynamic_ncols=True,
               disable=not config.progress, file=sys.stderr)
    started = time.perf_counter() - elapsed
    while frames < config.total_frames:
        iteration_start = time.perf_counter()
        batch, carry = collect(env, learner.actor, carry, config.rollout_steps)
        finished = episodes.add_batch(batch)
        update_multipliers(multipliers, finished)
        learner.loss.set_multipliers([multipliers[c].value for c in COSTS])
        learner.loss.set_imitation_coeff(imitation_coeff(config, frames))
        for group in learner.optimizer.param_groups:
            group["lr"] = learning_rate(config, frames)
        env.teacher_active = imitation_coeff(config, frames + batch.numel()) > 0
        shape_signals(batch, config, env.config.off_road_lane_cost)
        losses = ppo_update(learner, batch, config, generator)
        iteration += 1
        frames += batch.numel()

        summary = summarise([e for e in finished if not e.encounter])
        encounters = summarise([e for e in finished if e.encounter])
        row = {"iteration": iteration, "frames": frames,
               "time_s": time.perf_counter() - started,
               "frames_per_s": batch.numel() / (time.perf_counter() - iteration_start),
               "episodes": summary.episodes, "J_R": summary.J_R, "J_clane": summary.J_clane,
               "J_coll": summary.J_coll, "episode_length": summary.length,
               "encounter_episodes": encounters.episodes, "J_coll_encounter": encounters.J_coll,
               "lambda_lane": multipliers["lane"].value,
               "lambda_collision": multipliers["collision"].value,
               **losses, **action_columns(batch, config.action.name)}
        metrics.append(row)
        if live is not None:
            live.log_iteration(row)
        bar.update(batch.numel())
        bar.set_postfix_str(progress_text(row), refresh=False)

        if config.eval.every and (iteration % config.eval.every == 0
                                  or frames >= config.total_frames):
            if eval_env is None:
                eval_env = build_env(config, num_envs=config.eval.num_envs, seed=config.eval.seed)
            evaluations.append(evaluate(config, eval_env, learner, iteration, frames,
                                        time.perf_counter() - started))
        if config.record_every and iteration % config.record_every == 0:
            if record_env is None:
                record_env = build_env(config, num_envs=1, seed=config.eval.seed)
            recording = record_iteration(config, record_env, learner, multipliers, iteration)
            if live is not None and recording is not None:
                live.add_recording(recording)
        if iteration % config.checkpoint_every == 0 or frames >= config.total_frames:
            save_checkpoint(checkpoint_path, checkpoint_state(
                config, learner, multipliers, episodes, env, generator, carry,
                iteration=iteration, frames=frames, elapsed=time.perf_counter() - started))
    bar.close()
    if live is not None:
        live.close()
    env.close()
    for extra_env in (eval_env, record_env):
        if extra_env is not None:
            extra_env.close()
    lock.close()
    print(f"done: {frames} frames in {iteration} iterations; run directory: {run_dir}",
          flush=True)
    print_last_evaluation(evaluations.path, config)
    return run_dir


def lock_run_dir(run_dir: Path) -> io.TextIOWrapper:
    """Holds ``run_dir/.lock`` exclusively until the returned file is closed (or the process
    ends, even by a kill), so two processes never train one run.

    Raises:
        ConfigError: if another process holds the lock.
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    handle = (run_dir / ".lock").open("w")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir} is being trained by another "
                          "process; wait for it to finish or choose another run_dir") from None
    return handle


def print_last_evaluation(path: Path, config: TrainConfig) -> None:
    """One line on the latest evaluation in ``eval.csv``, if there is one."""
    if not path.exists():
        return
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        return
    last = rows[-1]
    verdict = "both constraints hold" if last["satisfied"] == "1" else "constraints violated"
    print(f"evaluation at {last['frames']} frames ({last['episodes']} episodes): "
          f"J_R {float(last['J_R']):.2f} m, J_clane {float(last['J_clane']):.3f} dm "
          f"(≤ {config.algo.lane.threshold}), J_coll {float(last['J_coll']):.3f} "
          f"(≤ {config.algo.collision.threshold}): {verdict}", flush=True)



def progress_text(row: dict[str, Any]) -> str:
    def show(value: float, digits: int) -> str:
        return "-" if math.isnan(value) else f"{value:.{digits}f}"

    return (f"J_R {show(row['J_R'], 2)} m  J_clane {show(row['J_clane'], 2)} dm  "
            f"J_coll {show(row['J_coll'], 2)}  λ {row['lambda_lane']:.2f}/"
            f"{row['lambda_collision']:.2f}")


def evaluate(config: TrainConfig, env: BatchedLaneKeepingEnv, learner: Learner, iteration: int,
             frames: int, time_s: float) -> dict[str, Any]:
    """Episodes of the sampled policy from the evaluation seed (spawns and action samples),
    as ``python -m crllk.evaluate`` plays them; whether both constraints hold."""
    began = time.perf_counter()
    env.set_seed(config.eval.seed)
    summary = run_episodes(env, learner.actor, config.eval.episodes, deterministic=False,
                           sample_seed=config.eval.seed).summary
    satisfied = (summary.J_clane <= config.algo.lane.threshold
                 and summary.J_coll <= config.algo.collision.threshold)
    return {"iteration": iteration, "frames": frames, "time_s": time_s, **summary.as_row(),
            "episode_length": summary.length, "satisfied": int(satisfied),
            "evaluation_s": time.perf_counter() - began}


def open_live_view(config: TrainConfig, run_dir: Path) -> LiveView | None:
    """The run's live view (``live``), or None; rerun is imported only when it is on. A live
    view that cannot start is a warning: training goes on."""
    if config.live == "none":
        return None
    from crllk.live import live_url, open_live

    live, problems = open_live(config.live, config.live_port, f"crllk-live-{run_dir.resolve()}",
                               {"J_clane": config.algo.lane.threshold,
                                "J_coll": config.algo.collision.threshold})
    for message in problems:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    if live is not None:
        print(f"live view: rerun --bind 127.0.0.1 --connect {live_url(config.live_port)}",
              flush=True)
    return live


def record_iteration(config: TrainConfig, env: BatchedLaneKeepingEnv, learner: Learner,
                     multipliers: dict[str, Multiplier], iteration: int) -> Path | None:
    """Records one deterministic evaluation episode to
    ``<run_dir>/recordings/iteration_<iteration>.rrd`` (and the viewer of ``viewer``, if any)
    and returns its path. Files of one run share a recording id, so opened together they line
    up on the ``iteration`` timeline. A recording that fails is a warning (and None): training
    goes on."""
    from crllk.record import record_episodes  # rerun is imported only when recording

    run_dir = config.resolved_run_dir()
    path = run_dir / "recordings" / f"iteration_{iteration:06d}.rrd"
    env.set_seed(config.eval.seed)
    try:
        report = record_episodes(env, learner.actor, 1, path, viewer=config.viewer,
                                 iteration=iteration,
                                 multipliers={c: m.value for c, m in multipliers.items()},
                                 recording_id=f"crllk-train-{run_dir.resolve()}")
    except Exception as err:  # a recording never ends a training run
        print(f"warning: recording at iteration {iteration} failed: {err}", file=sys.stderr,
              flush=True)
        return None
    for message in report.warnings:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    return path


# ----- checkpoints -------------------------------------------------------------------------
def checkpoint_state(config: TrainConfig, learner: Learner, multipliers: dict[str, Multiplier],
                     episodes: EpisodeAccumulator, env: BatchedLaneKeepingEnv,
                     generator: torch.Generator, carry: TensorDictBase, *, iteration: int,
                     frames: int, elapsed: float) -> dict[str, Any]:
    return {
        "iteration": iteration, "frames": frames, "elapsed": elapsed,
        "config": OmegaConf.to_container(OmegaConf.structured(config)),
        "actor": learner.actor.state_dict(),
        "critics": {name: critic.state_dict() for name, critic in learner.critics.items()},
        "optimizer": learner.optimizer.state_dict(),
        "multipliers": {name: m.state_dict() for name, m in multipliers.items()},
        "episodes": episodes.state_dict(),
        "env": env.sim_state(),
        "carry": carry.clone(),
        "torch_rng": torch.get_rng_state(),
        "generator": generator.get_state(),
    }


def restore(state: dict[str, Any], learner: Learner, multipliers: dict[str, Multiplier],
            episodes: EpisodeAccumulator, env: BatchedLaneKeepingEnv,
            generator: torch.Generator) -> None:
    learner.actor.load_state_dict(state["actor"])
    for name, critic in learner.critics.items():
        critic.load_state_dict(state["critics"][name])
    learner.optimizer.load_state_dict(state["optimizer"])
    for name, multiplier in multipliers.items():
        multiplier.load_state_dict(state["multipliers"][name])
    learner.loss.set_multipliers([multipliers[c].value for c in COSTS])
    episodes.load_state_dict(state["episodes"])
    env.load_sim_state(state["env"])
    torch.set_rng_state(state["torch_rng"])
    generator.set_state(state["generator"])


# ----- command line ------------------------------------------------------------------------
def register_tasks(store: ConfigStore, names: Iterable[str] | None = None) -> None:
    """Makes every ``tasks/<name>.yaml`` a choice of the ``task`` group (``task=<name>``)."""
    for name in task_names() if names is None else names:
        data = read_yaml(task_file(name))
        node = dict(data) if isinstance(data, dict) else {}
        node.setdefault("name", name)
        store.store(group="task", name=name, node=node)


def resolve_config(cfg: DictConfig) -> TrainConfig:
    """The validated config; a resumed run keeps its saved settings except
    :data:`RESUME_KEEPS`."""
    config = validate(cfg)
    saved = config.resolved_run_dir() / "config.yaml"
    if config.resume and saved.exists():
        stored = OmegaConf.load(saved)
        for key in RESUME_KEEPS:
            stored[key] = getattr(config, key)
        stored["resume"] = True
        stored["run_dir"] = str(config.resolved_run_dir())
        config = validate(stored)
    return config


register_tasks(ConfigStore.instance())


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def main(cfg: DictConfig) -> None:
    try:
        train(resolve_config(cfg))
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
