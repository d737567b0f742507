"""Gymnasium environments of the lane-keeping tasks, for libraries that speak Gymnasium.

``import crllk.gym`` registers, for each shipped task, ``crllk/<Task>-v0`` (the paper's
setting: camera pixels, discrete actions) and the variants ``crllk/<Task>-State-v0``,
``crllk/<Task>-Continuous-v0`` and ``crllk/<Task>-StateContinuous-v0``, e.g.
``gymnasium.make("crllk/ObstacleLoop-v0")``. ``crllk.gym.make_env(task, ...)`` takes any task
name or task or map file.

A step returns Gymnasium's ``(observation, reward, terminated, truncated, info)``: the reward
is the forward progress along the lane (m); ``terminated`` means the robot left the road, hit
an obstacle or became unstable (``info["termination"]`` says which), ``truncated`` the task's
time limit. Each constraint's per-step cost is in ``info`` by name (``info["cost_lane"]``,
``info["cost_collision"]``, ...) and their sum in ``info["cost"]``, the convention of
Safety-Gymnasium's conversion wrappers; :class:`SafetyStep` gives Safety-Gymnasium's six-tuple
``(observation, reward, cost, terminated, truncated, info)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import gymnasium
import numpy as np
from gymnasium import spaces

from crllk.paths import task_names
from crllk.tasks.config import TaskConfig
from crllk.tasks.constraints import cost_key
from crllk.tasks.lane_keeping import load

VARIANTS = {"": ("pixels", "discrete"), "-State": ("state", "discrete"),
            "-Continuous": ("pixels", "continuous"), "-StateContinuous": ("state", "continuous")}
"""Id suffix -> (observation, action)."""
RENDER_SIZE = (240, 320)
"""Height and width of ``render()``'s robot-camera image (pixels)."""


class LaneKeepingEnv(gymnasium.Env):
    """One lane-keeping task (:func:`crllk.load`) as a Gymnasium environment."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, task: str | Path = "small_loop", observation: str = "pixels",
                 action: str = "discrete", render_mode: str | None = None,
                 overrides: dict[str, Any] | None = None):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self._task_source, self._observation, self._action = task, observation, action
        self._overrides = overrides
        self._env = load(task, observation=observation, action=action, seed=None,
                         overrides=overrides)
        self.constraints = tuple(c.name for c in self._env.task.config.constraints)
        spec = self._env.observation_spec()[observation]
        if observation == "pixels":
            self.observation_space = spaces.Box(0, 255, spec.shape, np.uint8)
        else:
            self.observation_space = spaces.Box(-np.inf, np.inf, spec.shape, np.float32)
        if action == "discrete":
            self.action_space = spaces.Discrete(3)
        else:
            self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)

    @property
    def task_config(self) -> TaskConfig:
        """The task's settings (its map, constraints, horizon, ...)."""
        return self._env.task.config

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:  # spawns come from the task's own generator
            self._env.task.random.seed(seed)
        step = self._env.reset()
        return self._observation_of(step), {}

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        step = self._env.step(self._checked(action))
        outcome = self._env.task.episode.outcome
        info: dict[str, Any] = {cost_key(name): float(step.observation[cost_key(name)])
                                for name in self.constraints}
        info["cost"] = float(sum(info.values()))
        info["termination"] = outcome.termination
        terminated = step.last() and outcome.termination is not None
        truncated = step.last() and not terminated
        return (self._observation_of(step), float(step.reward), terminated, truncated, info)

    def _checked(self, action) -> int | np.ndarray:
        """``action`` as the task takes it.

        Raises:
            ValueError: for a discrete action that is not a whole number in the action space
                (``1.7`` is not action 1), or a continuous one that is not two finite numbers.
        """
        if self._action == "discrete":
            if not self.action_space.contains(action):
                raise ValueError(f"action: expected a whole number from 0 to "
                                 f"{self.action_space.n - 1}, got {action!r}")
            return int(action)
        try:
            value = np.asarray(action, dtype=np.float32)
        except (TypeError, ValueError):
            value = np.full(0, np.nan, dtype=np.float32)  # refused just below
        if value.shape != self.action_space.shape or not np.isfinite(value).all():
            raise ValueError(f"action: expected {self.action_space.shape[0]} finite numbers, "
                             f"got {action!r}")
        return value

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return self._env.physics.render_camera(*RENDER_SIZE)

    def close(self) -> None:
        self._env.physics.free_renderers()

    def _observation_of(self, step) -> np.ndarray:
        value = step.observation[self._observation]
        dtype = np.uint8 if self._observation == "pixels" else np.float32
        return np.asarray(value, dtype=dtype)


class SafetyStep(gymnasium.Wrapper):
    """Safety-Gymnasium's step: ``(observation, reward, cost, terminated, truncated, info)``,
    the cost taken from ``info["cost"]``."""

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        return observation, reward, info["cost"], terminated, truncated, info


def make_env(task: str | Path = "small_loop", **kwargs: Any) -> LaneKeepingEnv:
    """A :class:`LaneKeepingEnv` of any task name or task or map file."""
    return LaneKeepingEnv(task, **kwargs)


def environment_id(task: str, suffix: str = "") -> str:
    """``crllk/<Task><suffix>-v0`` of a task name: ``obstacle_loop`` -> ``ObstacleLoop``."""
    return "crllk/" + "".join(part.capitalize() for part in task.split("_")) + suffix + "-v0"


def register_all() -> list[str]:
    """Registers every shipped task in every variant; returns the ids."""
    ids = []
    for task in task_names():
        for suffix, (observation, action) in VARIANTS.items():
            env_id = environment_id(task, suffix)
            if env_id not in gymnasium.registry:
                gymnasium.register(env_id, entry_point=LaneKeepingEnv,
                                   kwargs={"task": task, "observation": observation,
                                           "action": action})
            ids.append(env_id)
    return ids


ENVIRONMENT_IDS = register_all()

__all__ = ["ENVIRONMENT_IDS", "LaneKeepingEnv", "SafetyStep", "environment_id", "make_env",
           "register_all"]
