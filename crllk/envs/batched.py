"""TorchRL environments over the lane-keeping tasks: many simulations batched in one ``EnvBase``.

``make_env(task, num_envs=N, ...)`` returns a :class:`BatchedLaneKeepingEnv` with batch size
``[N]``. It owns N (:class:`~crllk.sim.physics.Physics`,
:class:`~crllk.tasks.lane_keeping.LaneKeeping`) pairs built as :func:`crllk.load` builds one
(the scene is compiled once and the other physics share its ``MjModel``) and drives each through
the task hooks directly, skipping dm_control's ``Environment``. Keys after a step:

- observation: ``"pixels"`` (uint8 ``[N, H, W, 3]``, channels last as the camera delivers them;
  add ``ToTensorImage`` for channels-first float) or ``"state"`` (float32 ``[N, F]``, entries
  named by :func:`crllk.tasks.lane_keeping.state_feature_names`);
- reward-like (``[N, 1]`` float32, never in the observation): ``"reward"`` (forward progress
  along the lane, m) and ``"cost_<name>"`` for each constraint the task declares
  (:attr:`cost_keys`; by default ``"cost_lane"`` in dm and ``"cost_collision"``, 0 or 1);
- ``"terminated"`` (the task ended the episode: off road, collision, unstable physics),
  ``"truncated"`` (the ``horizon`` time limit was reached without termination) and
  ``"done" = terminated | truncated``, each bool ``[N, 1]``; ``"termination"`` (int64
  ``[N, 1]``) says why, as an index into :data:`TERMINATIONS` (0: not terminated).

Finished sub-environments are reset the TorchRL way: ``reset`` with a ``"_reset"`` mask (as
``step_and_maybe_reset``, ``rollout`` and the collectors pass it) resets only those.

Per-sub-environment details for evaluation and visualisation stay on the simulations:
``env.tasks[i].outcome`` (lane pose, signals), ``env.tasks[i].start_direction`` and
``hit_object``, ``env.physics[i]`` (pose, speeds) and ``env.step_counts[i]``;
:class:`crllk.rl.rollout.Rollout` shows each transition before finished ones reset.

Snapshots: ``env.sim_state()`` returns every simulation's full state (MuJoCo, task, spawn
generator, step counts, last observations) as plain values; ``env.load_sim_state(state)`` on an
env built with the same arguments continues exactly as the original would (training resume).

Seeding: sub-environment ``i`` draws its spawns from ``np.random.RandomState(s_i)`` where
``s_i = sub_env_seeds(seed, N)[i]`` (children of ``np.random.SeedSequence(seed)``), so
``crllk.load(task, seed=s_i, ...)`` reproduces sub-environment ``i`` step for step.

What the environments over simulations stepped elsewhere share (merging and splitting their
workers' snapshots, the mirrored teacher flag) lives in :mod:`crllk.envs.workers`. The rest stays
one file: it is one class, whose specs, reset, step, observation and snapshot methods all read
and write the same per-simulation arrays.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from dm_control.rl import control
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, TensorSpec, Unbounded
from torchrl.envs import EnvBase

from crllk.envs.workers import (
    SNAPSHOT_ARRAYS,
    MirroredTeacherFlag,
    merge_sim_states,
    split_sim_state,
)
from crllk.sim.camera_effects import apply_effects
from crllk.sim.physics import Physics
from crllk.tasks.config import TaskConfig, load_task_config
from crllk.tasks.follower import FollowerGains
from crllk.tasks.frames import FrameHistory
from crllk.tasks.lane_keeping import (
    ACTIONS,
    OBSERVATIONS,
    LaneKeeping,
    StepOutcome,
    command_history_length,
    physics_of,
    state_feature_names,
)
from crllk.tasks.teacher import Teacher

DONE_KEYS = ("done", "terminated", "truncated")
TERMINATIONS = (None, "off_road", "collision", "unstable")
"""The ``"termination"`` entry's codes: why the task ended the episode on this step."""


def sub_env_seeds(seed: int | None, num_envs: int) -> list[int]:
    """The spawn seed of each sub-environment: one 32-bit word from each of ``num_envs``
    children of ``np.random.SeedSequence(seed)`` (``None``: fresh OS entropy)."""
    children = np.random.SeedSequence(seed).spawn(num_envs)
    return [int(child.generate_state(1)[0]) for child in children]


class BatchedLaneKeepingEnv(EnvBase):
    """``num_envs`` lane-keeping simulations stepped in one process behind one ``EnvBase``."""

    def __init__(self, config: TaskConfig, *, num_envs: int = 1, observation: str = "pixels",
                 action: str = "discrete", seed: int | None = None,
                 privileged_state: bool = False, teacher: bool = False,
                 teacher_margin: float = FollowerGains.avoid_margin,
                 commands: bool = False, history: int = 1, history_stride: int = 1,
                 lane_pose: bool = False, device: torch.device | str = "cpu"):
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        if observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {observation!r}")
        if action not in ACTIONS:
            raise ValueError(f"action must be one of {ACTIONS}, got {action!r}")
        if history > 1 and observation != "pixels":
            raise ValueError(f"a frame history needs pixel observations, got {observation!r}")
        super().__init__(device=device, batch_size=torch.Size([num_envs]))
        self.config = config
        self.num_envs = num_envs
        self.observation_type = observation
        self.action_type = action
        self.physics = _build_physics(config, num_envs, share_renderers=observation == "pixels")
        self.tasks = [LaneKeeping(config, observation=observation, action=action, random=0)
                      for _ in range(num_envs)]
        self.n_sub_steps = control.compute_n_steps(config.control_timestep,
                                                   self.physics[0].timestep())
        self.step_counts = np.zeros(num_envs, dtype=np.int64)
        """Control steps taken in each sub-environment's current episode."""
        self.seeds: list[int] = []
        """The spawn seed of each sub-environment (see :func:`sub_env_seeds`)."""
        self._observations = np.zeros(self._observation_shape(), self._observation_dtype())
        self.history = (FrameHistory(num_envs, self._observations.shape[1:], history,
                                     history_stride) if history > 1 else None)
        """With ``history`` > 1, ``"pixels"`` stacks that many recent camera images,
        ``history_stride`` control steps apart, newest first (:class:`FrameHistory`)."""
        self.privileged_state = privileged_state and observation == "pixels"
        """Whether pixel observations come with the ``"state"`` features too (for critics)."""
        self._states = np.zeros((num_envs, len(state_feature_names(config))), np.float32)
        self.teachers = ([Teacher(config, task.obstacles, action, teacher_margin)
                          for task in self.tasks] if teacher else [])
        """With ``teacher``, observations carry ``"teacher_action"``: the privileged teacher's
        action (:mod:`crllk.tasks.teacher`) for the state observed, while :attr:`teacher_active`."""
        self.teacher_active = teacher
        self._teacher_actions = np.zeros((num_envs, *(() if action == "discrete" else (2,))),
                                         np.int64 if action == "discrete" else np.float32)
        self.reports_commands = commands
        """Whether observations carry ``"commands"``: the wheel duties (left, right) commanded
        in the last steps, newest first (those still in flight through the motor delay), as
        the policy's own memory of what it asked for."""
        self._commands = np.zeros((num_envs, 2 * command_history_length(config)), np.float32)
        self.constraints = config.constraints
        """The task's constraints (:mod:`crllk.tasks.constraints`)."""
        self.cost_keys = tuple(c.cost_key for c in config.constraints)
        """Reward-like keys of the per-step costs, next to ``"reward"``, in constraint order."""
        self.reports_encounters = config.spawn.encounters > 0
        """Whether observations carry ``"encounter"``: the episode started in front of an
        obstacle (``spawn.encounters``), so that metrics can leave such episodes out."""
        self.reports_lane_pose = lane_pose
        """Whether observations carry ``"lane_lateral"`` and ``"in_lane"``, the lane pose the
        community's metrics are measured from (:mod:`crllk.evaluation.community`)."""
        self._make_specs()
        self._set_seed(seed)

    # ----- specs ------------------------------------------------------------------------
    def _observation_shape(self) -> tuple[int, ...]:
        if self.observation_type == "pixels":
            cam = self.config.camera
            return (self.num_envs, cam.height, cam.width, 3)
        return (self.num_envs, len(state_feature_names(self.config)))

    def _observation_dtype(self) -> type:
        return np.uint8 if self.observation_type == "pixels" else np.float32

    def _make_specs(self) -> None:
        n = self.batch_size
        shape = self._observation_shape()
        if self.history is not None:
            shape = (*shape[:-1], self.history.channels)
        if self.observation_type == "pixels":
            obs: TensorSpec = Bounded(0, 255, shape=shape, dtype=torch.uint8, device=self.device)
        else:
            obs = Unbounded(shape=shape, dtype=torch.float32, device=self.device)
        entries = {self.observation_type: obs}
        if self.privileged_state:
            entries["state"] = Unbounded(shape=self._states.shape, dtype=torch.float32,
                                         device=self.device)
        entries["termination"] = Categorical(len(TERMINATIONS), shape=(*n, 1),
                                             dtype=torch.int64, device=self.device)
        if self.reports_encounters:
            entries["encounter"] = Categorical(2, shape=(*n, 1), dtype=torch.bool,
                                               device=self.device)
        if self.teachers:
            entries["teacher_action"] = self._action_spec_of(n)
        if self.reports_lane_pose:
            entries["lane_lateral"] = Unbounded(shape=(*n, 1), dtype=torch.float32,
                                                device=self.device)
            entries["in_lane"] = Categorical(2, shape=(*n, 1), dtype=torch.bool,
                                             device=self.device)
        if self.reports_commands:
            entries["commands"] = Bounded(-1.0, 1.0, shape=self._commands.shape,
                                          dtype=torch.float32, device=self.device)
        self.observation_spec = Composite(entries, shape=n, device=self.device)
        self.action_spec = self._action_spec_of(n)
        self.reward_spec = Composite(
            {key: Unbounded(shape=(*n, 1), dtype=torch.float32, device=self.device)
             for key in ("reward", *self.cost_keys)}, shape=n, device=self.device)
        self.done_spec = Composite(
            {key: Categorical(2, shape=(*n, 1), dtype=torch.bool, device=self.device)
             for key in DONE_KEYS}, shape=n, device=self.device)

    def _action_spec_of(self, n: torch.Size) -> TensorSpec:
        if self.action_type == "discrete":
            return Categorical(3, shape=n, dtype=torch.int64, device=self.device)
        return Bounded(-1.0, 1.0, shape=(*n, 2), dtype=torch.float32, device=self.device)

    # ----- seeding ----------------------------------------------------------------------
    def _set_seed(self, seed: int | None) -> None:
        """Reseed every sub-environment's spawn generator; takes effect at the next reset."""
        self.set_spawn_seeds(sub_env_seeds(seed, self.num_envs))

    def set_spawn_seeds(self, seeds: Sequence[int]) -> None:
        """Reseed sub-environment ``i``'s spawn generator with ``seeds[i]`` (takes effect at
        the next reset): a slice of a larger env's :func:`sub_env_seeds`, so that a worker of
        :class:`crllk.envs.parallel.ParallelLaneKeepingEnv` plays its share of the
        simulations exactly as the one-process env would."""
        if len(seeds) != self.num_envs:
            raise ValueError(f"{len(seeds)} spawn seeds for {self.num_envs} simulations")
        self.seeds = [int(s) for s in seeds]
        for task, sub_seed in zip(self.tasks, self.seeds, strict=True):
            task.random.seed(sub_seed)

    def set_teacher_active(self, active: bool) -> None:
        """Sets :attr:`teacher_active` (a method, so that worker processes can be told)."""
        self.teacher_active = bool(active)

    # ----- reset and step ---------------------------------------------------------------
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        """Reset the sub-environments flagged by ``"_reset"`` (all of them without it)."""
        mask = None if tensordict is None else tensordict.get("_reset", None)
        if mask is None:
            indices: Sequence[int] = range(self.num_envs)
        else:
            indices = mask.reshape(self.num_envs).nonzero().flatten().tolist()
        for i in indices:
            self._reset_one(i)
        return self._restarted(indices)

    def observe_again(self) -> TensorDictBase:
        """Every simulation's observation taken again as it stands, returned as a reset
        returns it: for episodes whose scene was changed after their reset (a fleet's robots
        placed in each other's simulations, :mod:`crllk.evaluation.fleet`)."""
        for i, (physics, task) in enumerate(zip(self.physics, self.tasks, strict=True)):
            self._observe(i, physics, task)
        return self._restarted(range(self.num_envs))

    def _restarted(self, indices: Sequence[int]) -> TensorDictBase:
        """What a reset of sub-environments ``indices`` returns, their observations taken."""
        self._apply_camera_effects(indices)
        if self.history is not None:
            self.history.restart(indices, self._observations[list(indices)])
        false = torch.zeros((self.num_envs, 1), dtype=torch.bool)
        out = {**self._observation_entries(), **{key: false.clone() for key in DONE_KEYS},
               "termination": torch.zeros((self.num_envs, 1), dtype=torch.int64)}
        return self._tensordict(out)

    def _reset_one(self, i: int) -> None:
        physics, task = self.physics[i], self.tasks[i]
        with physics.reset_context():
            task.initialize_episode(physics)
        self._observe(i, physics, task)
        self.step_counts[i] = 0

    def _observe(self, i: int, physics: Physics, task: LaneKeeping) -> None:
        """Store sub-environment ``i``'s observation (and privileged state features); a camera
        image without its effects (:meth:`_apply_camera_effects` adds them)."""
        if self.observation_type == "pixels":
            self._observations[i] = task.camera_image(physics)
        else:
            self._observations[i] = task.state_feature_list(physics)
        if self.privileged_state:
            self._states[i] = task.state_feature_list(physics)
        if self.reports_commands:
            self._commands[i] = [value for duty in task.command_history for value in duty]
        if self.teacher_active and self.teachers:
            self._teacher_actions[i] = self.teachers[i].action(physics, task.movers)
        elif self.teachers:  # none left over while off: a resumed run sees what a straight one does
            self._teacher_actions[i] = 0

    def _apply_camera_effects(self, indices: Sequence[int]) -> None:
        """The camera effects of the episodes of sub-environments ``indices`` (randomised JPEG
        compression and sensor noise) on their stored images, in one vectorised call."""
        if self.observation_type != "pixels":
            return
        effects = [self.tasks[i].frame_effects() for i in indices]
        if any(effect is not None for effect in effects):
            chosen = list(indices)
            self._observations[chosen] = apply_effects(self._observations[chosen], effects)

    def _observation_entries(self) -> dict[str, torch.Tensor]:
        observation = (self._observations.copy() if self.history is None
                       else self.history.stacked())
        entries = {self.observation_type: torch.from_numpy(observation)}
        if self.privileged_state:
            entries["state"] = torch.from_numpy(self._states.copy())
        if self.reports_encounters:
            entries["encounter"] = torch.tensor([[task.encounter] for task in self.tasks])
        if self.teachers:
            entries["teacher_action"] = torch.from_numpy(self._teacher_actions.copy())
        if self.reports_lane_pose:
            outcomes = [task.outcome for task in self.tasks]
            entries["lane_lateral"] = torch.tensor([[o.lateral] for o in outcomes],
                                                   dtype=torch.float32)
            entries["in_lane"] = torch.tensor([[o.in_lane] for o in outcomes])
        if self.reports_commands:
            entries["commands"] = torch.from_numpy(self._commands.copy())
        return entries

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        """One control step of every sub-environment.

        Each phase runs over all sub-environments before the next (commands, physics, task
        bookkeeping and observations): the interpreter and MuJoCo each stay warm in the CPU
        caches, which is markedly faster than interleaving them per sub-environment."""
        actions = tensordict.get("action").detach().cpu().tolist()
        for physics, task, action in zip(self.physics, self.tasks, actions, strict=True):
            task.before_step(action, physics)
        for physics in self.physics:
            physics.step(self.n_sub_steps)
        for i, (physics, task) in enumerate(zip(self.physics, self.tasks, strict=True)):
            task.after_step(physics)
            self._observe(i, physics, task)
        self._apply_camera_effects(range(self.num_envs))
        if self.history is not None:
            self.history.push(self._observations)
        self.step_counts += 1
        return self._tensordict(self._step_outputs([task.outcome for task in self.tasks]))

    def _step_outputs(self, outcomes: list[StepOutcome]) -> dict[str, torch.Tensor]:
        """The step's observation, reward-like and done entries, each ``[N, ...]``."""
        rewards = np.array([[o.progress for o in outcomes],
                            *([o.cost(c) for o in outcomes] for c in self.constraints)],
                           dtype=np.float32)
        columns = torch.from_numpy(rewards[:, :, None])
        codes = np.array([[TERMINATIONS.index(o.termination)] for o in outcomes])
        terminated = codes > 0
        truncated = (self.step_counts >= self._horizons())[:, None] & ~terminated
        return {**self._observation_entries(), "reward": columns[0],
                **dict(zip(self.cost_keys, columns[1:], strict=True)),
                "termination": torch.from_numpy(codes),
                "terminated": torch.from_numpy(terminated),
                "truncated": torch.from_numpy(truncated),
                "done": torch.from_numpy(terminated | truncated)}

    def _horizons(self) -> np.ndarray:
        """Each sub-environment's time limit (steps, :meth:`TaskConfig.step_limit`)."""
        return np.array([self.config.step_limit(task.encounter) for task in self.tasks])

    def _tensordict(self, entries: dict[str, torch.Tensor]) -> TensorDict:
        """``entries`` on the env's device (set, so TorchRL need not move them again)."""
        return TensorDict(entries, batch_size=self.batch_size, device=self.device)

    # ----- snapshots --------------------------------------------------------------------
    def sim_state(self) -> dict[str, Any]:
        """A snapshot of everything that determines the env's future: each sub-environment's
        full MuJoCo state (delay history included), task hook state and spawn generator, the
        step counts, seeds and last observations. Plain Python values and tensors only, so
        ``torch.save`` / ``torch.load`` (``weights_only``) round-trip it."""
        history = ({} if self.history is None
                   else {"history_images": torch.from_numpy(self.history.images.copy())})
        return {**self._identity(), **history,
                "seeds": list(self.seeds),
                "step_counts": self.step_counts.tolist(),
                "observations": torch.from_numpy(self._observations.copy()),
                "states": torch.from_numpy(self._states.copy()),
                "sub_envs": [{"physics": physics.full_state(),
                              "instabilities": physics.instabilities,
                              "task": task.episode_state()}
                             for physics, task in zip(self.physics, self.tasks, strict=True)]}

    def load_sim_state(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`sim_state` taken from an env built with the same arguments; the
        env then steps exactly as the original did from the snapshot on.

        Raises:
            ValueError: if the snapshot's task, num_envs, observation or action differ.
        """
        for key, expected in self._identity().items():
            if state.get(key) != expected:
                raise ValueError(f"snapshot {key} is {state.get(key)!r}, this env has "
                                 f"{expected!r}: restore into an env built with the same "
                                 "arguments")
        for physics, task, sub in zip(self.physics, self.tasks, state["sub_envs"], strict=True):
            task.load_episode_state(sub["task"], physics)  # its randomisation first
            physics.set_full_state(sub["physics"])
            physics.instabilities = sub["instabilities"]
        self.seeds = list(state["seeds"])
        self.step_counts[:] = state["step_counts"]
        self._observations[:] = state["observations"].numpy()
        self._states[:] = state["states"].numpy()
        if self.history is not None:
            self.history.images[:] = state["history_images"].numpy()

    def _identity(self) -> dict[str, Any]:
        """The constructor arguments a snapshot must agree on."""
        identity = {"task": self.config.name, "num_envs": self.num_envs,
                    "observation": self.observation_type, "action": self.action_type,
                    "privileged_state": self.privileged_state, "teacher": bool(self.teachers),
                    "commands": self.reports_commands}
        if self.history is not None:  # only then, so older snapshots still load
            identity["history"] = [self.history.count, self.history.stride]
        return identity

    # ----- teardown ---------------------------------------------------------------------
    def close(self, *, raise_if_closed: bool = True) -> None:
        """Release the GL contexts of the camera renderers."""
        for physics in self.physics:
            physics.free_renderers()
        super().close(raise_if_closed=raise_if_closed)


def _build_physics(config: TaskConfig, num_envs: int, *, share_renderers: bool) -> list[Physics]:
    """Compile the scene once; the other physics share its ``MjModel`` (and, for pixels, its
    camera renderers: one GL context renders every sub-environment's data in turn)."""
    first = physics_of(config)
    copies = [first.copy(share_model=True) for _ in range(num_envs - 1)]
    if share_renderers:
        for physics in copies:
            physics._renderers = first._renderers  # same MjModel: one GL context for all
    return [first, *copies]


def make_env(task: str | Path, *, num_envs: int = 1, observation: str = "pixels",
             action: str = "discrete", seed: int | None = None,
             overrides: dict[str, Any] | None = None, privileged_state: bool = False,
             teacher: bool = False, teacher_margin: float = FollowerGains.avoid_margin,
             commands: bool = False, history: int = 1, history_stride: int = 1,
             lane_pose: bool = False, device: torch.device | str = "cpu"
             ) -> BatchedLaneKeepingEnv:
    """A TorchRL environment with ``num_envs`` lane-keeping simulations in one process.

    Args:
        task: a task name or the path of a task or Duckietown map file (as :func:`crllk.load`).
        num_envs: simulations stepped together; the env's batch size is ``[num_envs]``.
        observation: ``"pixels"`` (uint8 ``[N, H, W, 3]``) or ``"state"`` (float32 ``[N, F]``).
        action: ``"discrete"`` (``Categorical(3)``, shape ``[N]``), ``"continuous"``
            ((velocity, steering) in [-1, 1], shape ``[N, 2]``) or ``"duty"`` (wheel duties).
        seed: sub-environment ``i`` spawns from ``sub_env_seeds(seed, num_envs)[i]``.
        overrides: task settings to replace, e.g. ``{"horizon": 64}``.
        privileged_state: with pixels, also return the ``"state"`` features (float32
            ``[N, F]``) for critics that may see what the policy cannot (asymmetric
            actor-critic); the policy still reads only ``"pixels"``.
        teacher: also return ``"teacher_action"``, the privileged teacher's action for each
            observation (:mod:`crllk.tasks.teacher`), for an imitation loss.
        teacher_margin: the gap (m) the teacher keeps beside obstacles it passes.
        commands: also return ``"commands"`` (float32 ``[N, 2K]``), the wheel duties of the
            last K steps, newest first (K covers the motor delay).
        history: pixels only: ``"pixels"`` stacks this many recent camera images, newest
            first (uint8 ``[N, H, W, 3 * history]``), a memory of what went out of view.
        history_stride: control steps between the stacked images.
        lane_pose: also return ``"lane_lateral"`` (float32 ``[N, 1]``, the signed offset (m)
            from the lane centre after the step, positive right) and ``"in_lane"`` (bool
            ``[N, 1]``: on the road, centre inside its own lane), for evaluations.
        device: where the returned tensors live (simulation runs on the CPU).
    """
    config = load_task_config(task, overrides)
    return BatchedLaneKeepingEnv(config, num_envs=num_envs, observation=observation,
                                 action=action, seed=seed, privileged_state=privileged_state,
                                 teacher=teacher, teacher_margin=teacher_margin, commands=commands,
                                 history=history, history_stride=history_stride,
                                 lane_pose=lane_pose, device=device)


__all__ = ["SNAPSHOT_ARRAYS", "TERMINATIONS", "BatchedLaneKeepingEnv", "MirroredTeacherFlag",
           "make_env", "merge_sim_states", "split_sim_state", "sub_env_seeds"]
