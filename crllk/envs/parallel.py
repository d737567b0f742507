"""The simulations of one run stepped in several processes, behind one ``EnvBase``.

:class:`ParallelLaneKeepingEnv` starts ``W`` worker processes (spawned), each holding a
:class:`~crllk.envs.batched.BatchedLaneKeepingEnv` of ``n`` simulations, and presents them as
one env of batch size ``[W * n]``: simulation ``w * n + j`` is simulation ``j`` of worker
``w``. Its tensordicts have the keys and layout of a one-process env of ``W * n`` simulations,
so the policy, the episode statistics and the PPO update do not see the difference.

Each worker is driven through its own pipe: a step sends it its slice of the actions and
*blocks* until every worker has answered with its outputs (plain numpy arrays, a few KB per
simulation). Nothing polls: on a two-core machine a parent spin-waiting on shared-memory flags
(as TorchRL's ``ParallelEnv`` does) takes one core from the two workers and leaves pixel
collection slower with two workers than with one. The workers inherit ``LP_NUM_THREADS=0``
from ``import crllk`` (llvmpipe draws on each worker's own thread) and ignore Ctrl-C: the
parent stops them.

Workers are built by a picklable factory (a module-level function and its keyword arguments per
worker). :meth:`~ParallelLaneKeepingEnv.sim_state` gathers the workers' snapshots into the one
snapshot a one-process env would take (:func:`~crllk.envs.workers.merge_sim_states`), and
:meth:`~ParallelLaneKeepingEnv.load_sim_state` hands each worker its slice.
"""

from __future__ import annotations

import multiprocessing
import signal
import traceback
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.envs import EnvBase

from crllk.envs.batched import BatchedLaneKeepingEnv, sub_env_seeds
from crllk.envs.workers import MirroredTeacherFlag, merge_sim_states, split_sim_state
from crllk.errors import ConfigError, MapError

ANSWER_TIMEOUT_S = 600.0
"""How long a worker may take to answer one command (s; starting takes the longest: imports of
10–30 s on a loaded machine) before it is taken for hung."""
CLOSE_TIMEOUT_S = 10.0
"""How long a worker may take to release its renderers and exit before it is terminated (s)."""


@dataclass
class TaskView:
    """What evaluation reads of a worker's task after each step (its episode's details)."""

    start_direction: str | None = None
    """The loop direction the episode started in (``"intended"``, ``"reverse"`` or None)."""
    hit_object: int | None = None
    """The map object the episode ended on (an index, or None)."""
    hit_mover: int | None = None
    """The moving agent the episode ended on (an index: vehicles, then pedestrians; or None)."""


class WorkerError(RuntimeError):
    """A worker process failed (its error's last line in the message, its traceback in the
    exception's notes), exited, or stopped answering."""


class ParallelLaneKeepingEnv(MirroredTeacherFlag, EnvBase):
    """``len(worker_kwargs)`` worker processes, each a :class:`BatchedLaneKeepingEnv` built by
    ``create_env_fn(**worker_kwargs[w])`` (every worker with as many simulations), stepped
    together as one env of batch size ``[workers * n]``.

    Args:
        create_env_fn: a module-level function (spawned workers import it) returning a
            :class:`BatchedLaneKeepingEnv`.
        worker_kwargs: its keyword arguments, one mapping per worker.
        num_threads: torch threads of this process (None: unchanged); each worker runs with
            one.

    The workers are daemonic: they end with this process even if :meth:`close` is never
    called (a run that fails half-way).
    """

    def __init__(self, create_env_fn: Callable[..., BatchedLaneKeepingEnv],
                 worker_kwargs: Sequence[dict[str, Any]], *, num_threads: int | None = None):
        workers = len(worker_kwargs)
        if workers < 1:
            raise ValueError("at least one worker is needed")
        if num_threads is not None:
            torch.set_num_threads(num_threads)
        self._running = False
        self._pipes: list[Connection] = []
        self._processes: list[multiprocessing.process.BaseProcess] = []
        try:
            with _standard_start_method():
                context = multiprocessing.get_context("spawn")
                for kwargs in worker_kwargs:
                    parent, child = context.Pipe()
                    process = context.Process(target=_serve, daemon=True,
                                              args=(child, create_env_fn, kwargs))
                    process.start()
                    child.close()
                    self._pipes.append(parent)
                    self._processes.append(process)
            infos = self._gather()
        except BaseException:
            self._stop()
            raise
        per_worker = infos[0]["num_envs"]
        if any(info["num_envs"] != per_worker for info in infos):
            self._stop()
            raise ValueError("every worker must hold as many simulations")
        super().__init__(device="cpu", batch_size=torch.Size([workers * per_worker]))
        self.workers, self.per_worker, self.num_envs = workers, per_worker, workers * per_worker
        first = infos[0]
        self.config = first["config"]
        """The task's :class:`~crllk.tasks.config.TaskConfig` (the workers')."""
        self.constraints = self.config.constraints
        self.cost_keys = tuple(c.cost_key for c in self.constraints)
        self._teacher_active = bool(first["teacher_active"])
        self.action_type: str = first["action_type"]
        """The workers' action type (:data:`crllk.tasks.actions.ACTIONS`)."""
        flat = torch.Size([self.num_envs])
        self.observation_spec = _flatten(first["observation_spec"], workers, flat)
        self.action_spec = _flatten(first["action_spec"], workers, flat)
        self.reward_spec = _flatten(first["reward_spec"], workers, flat)
        self.done_spec = _flatten(first["done_spec"], workers, flat)
        self.tasks = [TaskView() for _ in range(self.num_envs)]
        """Each simulation's :class:`TaskView` as of the last step or reset."""
        self._closed = False

    # ----- talking to the workers ---------------------------------------------------------
    def _gather(self) -> list[Any]:
        """Every worker's answer to the last command (blocking), in worker order.

        Raises:
            ConfigError: bad input a worker found (a task or map file), as it was raised there.
            WorkerError: with the first failing worker's traceback, or if one exited.
        """
        answers: list[Any] = []
        failure: Exception | None = None
        for index, pipe in enumerate(self._pipes):
            try:
                if not pipe.poll(ANSWER_TIMEOUT_S):  # waits in the kernel, never spins
                    raise WorkerError(f"simulation worker {index} did not answer within "
                                      f"{ANSWER_TIMEOUT_S:.0f} s")
                status, value = pipe.recv()
            except (EOFError, OSError):
                self._processes[index].join(CLOSE_TIMEOUT_S)
                code = self._processes[index].exitcode
                status, value = "error", f"the process exited (exit code {code})"
            except BaseException:  # a hung worker, Ctrl-C: answers in flight would be stale
                self._stop()
                raise
            if status == "config_error" and failure is None:
                kind, source, field, problem = value
                failure = kind(source, field, problem)
            elif status == "error" and failure is None:
                lines = str(value).strip().splitlines() or ["?"]
                failure = WorkerError(f"simulation worker {index} failed: {lines[-1]}")
                failure.add_note(f"the worker's traceback:\n{value}")
            answers.append(value)
        if failure is not None:
            raise failure
        return answers

    def _call(self, name: str, arguments: Sequence[Sequence[Any]] | None = None) -> list[Any]:
        """Method ``name`` of every worker's env, worker ``w`` with ``arguments[w]`` (none
        without), or the attribute ``name``; their results in worker order."""
        self._check_idle()
        for index, pipe in enumerate(self._pipes):
            pipe.send(("call", (name, () if arguments is None else tuple(arguments[index]))))
        return self._gather()

    def run(self, function: Callable[..., Any], arguments: Sequence[Sequence[Any]]) -> list[Any]:
        """``function(env, *arguments[w])`` in every worker ``w``, on its own env, all at
        once; the results in worker order. ``function`` must be a module-level function (the
        workers import it); what it takes and returns crosses a pipe (keep it to numpy
        arrays and plain values)."""
        self.start(function, arguments)
        return self.finish()

    def start(self, function: Callable[..., Any], arguments: Sequence[Sequence[Any]]) -> None:
        """Starts :meth:`run` and returns at once: the workers compute while this process
        does something else; :meth:`finish` waits for their results. Nothing else may be
        asked of the workers meanwhile.

        Raises:
            RuntimeError: if a started run has not been finished.
        """
        self._check_idle()
        self._running = True  # before sending: a send that fails leaves workers computing
        for pipe, args in zip(self._pipes, arguments, strict=True):
            pipe.send(("run", (function, tuple(args))))

    def finish(self) -> list[Any]:
        """The results of the run :meth:`start` started, in worker order (blocking)."""
        if not self._running:
            raise RuntimeError("no run was started")
        self._running = False
        return self._gather()

    @property
    def running(self) -> bool:
        """Whether a started run has not been finished."""
        return self._running

    def _check_idle(self) -> None:
        """Raises RuntimeError while a started run is unfinished (its answers would come
        first)."""
        if self._running:
            raise RuntimeError("the workers are running a started run: finish() it first")

    def _send_teacher_active(self, active: bool) -> None:
        self._call("set_teacher_active", [[active]] * self.workers)

    @property
    def seeds(self) -> list[int]:
        """The spawn seed of each simulation, in order."""
        return [seed for worker in self._call("seeds") for seed in worker]

    # ----- reset and step -----------------------------------------------------------------
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        self._check_idle()
        mask = None if tensordict is None else tensordict.get("_reset", None)
        masks = (None if mask is None
                 else mask.reshape(self.workers, self.per_worker).numpy())
        for index, pipe in enumerate(self._pipes):
            pipe.send(("reset", None if masks is None else masks[index]))
        return self._joined(self._gather())

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        self._check_idle()
        actions = tensordict.get("action").detach().cpu().numpy()
        for pipe, share in zip(self._pipes, np.split(actions, self.workers), strict=True):
            pipe.send(("step", share))
        return self._joined(self._gather())

    def _joined(self, outputs: list[tuple[dict[str, np.ndarray], list[tuple]]]) -> TensorDict:
        """The workers' outputs as one tensordict of every simulation, in order; their tasks'
        details into :attr:`tasks`."""
        details = [detail for _, worker in outputs for detail in worker]
        for view, (direction, hit, mover) in zip(self.tasks, details, strict=True):
            view.start_direction, view.hit_object, view.hit_mover = direction, hit, mover
        arrays = [out for out, _ in outputs]
        return TensorDict({key: torch.from_numpy(np.concatenate([out[key] for out in arrays]))
                           for key in arrays[0]}, batch_size=self.batch_size,
                          device=self.device)

    def _set_seed(self, seed: int | None) -> None:
        """Reseed every simulation's spawn generator as a one-process env of as many
        simulations would (:func:`sub_env_seeds`), each worker its slice."""
        seeds = sub_env_seeds(seed, self.num_envs)
        n = self.per_worker
        self._call("set_spawn_seeds", [[seeds[w * n:(w + 1) * n]] for w in range(self.workers)])

    # ----- snapshots ----------------------------------------------------------------------
    def sim_state(self) -> dict[str, Any]:
        """The workers' snapshots as one: what a one-process env of all the simulations would
        return (:meth:`BatchedLaneKeepingEnv.sim_state`)."""
        return merge_sim_states(self._call("sim_state"))

    def load_sim_state(self, state: dict[str, Any]) -> None:
        """Restores a :meth:`sim_state` (of this env or of a one-process env of as many
        simulations), each worker its slice."""
        parts = split_sim_state(state, [self.per_worker] * self.workers)
        self._call("load_sim_state", [[part] for part in parts])

    # ----- teardown -----------------------------------------------------------------------
    def close(self, *, raise_if_closed: bool = True) -> None:
        """Stops the worker processes (each releases its renderers first)."""
        if not getattr(self, "_closed", True):
            self._stop()
        super().close(raise_if_closed=raise_if_closed)

    def _stop(self) -> None:
        self._closed = True
        if self._running:  # take the answers of a started run, so its workers can exit
            self._running = False
            for pipe in self._pipes:
                with suppress(OSError, EOFError):
                    if pipe.poll(CLOSE_TIMEOUT_S):
                        pipe.recv()
        for pipe in self._pipes:
            with suppress(OSError):  # a worker that already exited
                pipe.send(("close", None))
        for process, pipe in zip(self._processes, self._pipes, strict=True):
            process.join(CLOSE_TIMEOUT_S)
            if process.is_alive():
                process.terminate()
                process.join()
            pipe.close()


def _serve(pipe: Connection, create_env_fn: Callable[..., BatchedLaneKeepingEnv],
           kwargs: dict[str, Any]) -> None:
    """A worker: builds its env, reports what the parent needs to know of it, then answers
    commands until ``close`` (or until the parent goes away)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    torch.set_num_threads(1)
    try:
        env = create_env_fn(**kwargs)
        pipe.send(("ok", {"num_envs": env.num_envs, "config": env.config,
                          "teacher_active": env.teacher_active,
                          "action_type": env.action_type,
                          "observation_spec": env.observation_spec,
                          "action_spec": env.action_spec, "reward_spec": env.reward_spec,
                          "done_spec": env.done_spec}))
    except BaseException as error:  # reported to the parent, which raises
        pipe.send(_failure(error))
        return
    batch = env.batch_size
    try:
        while True:
            try:
                command, argument = pipe.recv()
            except EOFError:
                return
            if command == "close":
                return
            try:
                if command == "step":
                    action = TensorDict({"action": torch.from_numpy(argument)}, batch_size=batch)
                    answer: Any = (_arrays(env._step(action)), _details(env))
                elif command == "reset":
                    mask = (None if argument is None else TensorDict(
                        {"_reset": torch.from_numpy(argument).reshape(-1, 1)}, batch_size=batch))
                    answer = (_arrays(env._reset(mask)), _details(env))
                elif command == "run":
                    function, arguments = argument
                    answer = function(env, *arguments)
                else:
                    name, arguments = argument
                    attribute = getattr(env, name)
                    answer = attribute(*arguments) if callable(attribute) else attribute
            except Exception as error:  # reported to the parent, which raises
                pipe.send(_failure(error))
            else:
                try:
                    pipe.send(("ok", answer))
                except Exception as error:  # an answer that cannot be pickled
                    pipe.send(_failure(error))
    finally:
        env.close()


def _failure(error: BaseException) -> tuple[str, Any]:
    """What a worker sends for ``error``: bad input as its parts (the parent raises it again,
    one line for the user), anything else as its traceback."""
    if isinstance(error, ConfigError):
        kind = type(error) if type(error) in (ConfigError, MapError) else ConfigError
        return "config_error", (kind, error.source, error.field, error.problem)
    return "error", traceback.format_exc()


def _details(env: BatchedLaneKeepingEnv) -> list[tuple[str | None, int | None, int | None]]:
    """Each task's :class:`TaskView` fields (a few bytes per simulation)."""
    return [(task.start_direction, task.hit_object, task.hit_mover) for task in env.tasks]


def _arrays(tensordict: TensorDictBase) -> dict[str, np.ndarray]:
    """A flat tensordict's entries as numpy arrays (what crosses the pipe)."""
    return {key: value.numpy() for key, value in tensordict.items()}


@contextmanager
def _standard_start_method() -> Iterator[None]:
    """Processes started meanwhile can be spawned. A spawned child takes its parent's global
    start method, and inside a joblib (loky) worker that is ``"loky"``, which a child that
    is not loky's own cannot find: it would exit before running anything."""
    current = multiprocessing.get_start_method(allow_none=True)
    if current is None or current in multiprocessing.get_all_start_methods():
        yield
        return
    multiprocessing.set_start_method("spawn", force=True)
    try:
        yield
    finally:
        multiprocessing.set_start_method(current, force=True)


def _flatten(spec: Any, workers: int, shape: torch.Size) -> Any:
    """A worker's ``spec`` of batch ``[n, ...]`` as the batch ``[workers * n, ...]``."""
    return spec.expand(workers, *spec.shape).reshape(*shape, *spec.shape[1:])


LaneKeepingEnv = BatchedLaneKeepingEnv | ParallelLaneKeepingEnv
"""The simulations of a run on this machine: in this process or in worker processes (the same
keys, layout and episodes either way)."""

__all__ = ["LaneKeepingEnv", "ParallelLaneKeepingEnv", "TaskView", "WorkerError"]
