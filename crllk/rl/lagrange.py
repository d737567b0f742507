"""Lagrange multipliers for the cost constraints, one small object per constraint.

A multiplier knows only its threshold α, its own update rule and its state; it knows nothing of
networks, losses or loggers. The training loop feeds it cost estimates Ĵ_C (one per finished
episode) and reads back ``value``; the loss receives that value.

Two rules share one interface (``value``, ``update``, ``state_dict``, ``from_state_dict``):

* :class:`LagrangeMultiplier`, projected dual ascent::

      λ ← clip(λ + η·(Ĵ_C − α), 0, λ_max)

  λ rises while the constraint is violated (Ĵ_C > α) and falls, down to 0, while it holds.
* :class:`PIDLagrangeMultiplier`, the PID Lagrangian of Stooke, Achiam and Abbeel (2020),
  "Responsive Safety in Reinforcement Learning by PID Lagrangian Methods", Algorithm 2.

``frozen=True`` turns either into a fixed weight (the PPO-D / PPO-C baselines).
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, Literal, Self

Schedule = Literal["episode", "batch"]
MultiplierKind = Literal["dual", "pid"]

_SCHEDULES: tuple[str, ...] = ("episode", "batch")


def _require_finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value}")
    return value


def _require_non_negative(name: str, value: float) -> float:
    value = _require_finite(name, value)
    if value < 0.0:
        raise ValueError(f"{name} must be >= 0, got {value}")
    return value


def _as_estimates(estimates: Sequence[float] | float) -> list[float]:
    """Returns the estimates as a list of finite floats (a scalar becomes a one-item list)."""
    if isinstance(estimates, int | float):
        values = [float(estimates)]
    else:
        try:
            values = [float(x) for x in estimates]
        except TypeError:  # a 0-d tensor or array is not iterable
            values = [float(estimates)]  # type: ignore[arg-type]
    for value in values:
        _require_finite("cost estimate", value)
    return values


class _Multiplier(abc.ABC):
    """What every multiplier shares: threshold, bounds, schedule, freezing and the state format.

    Subclasses implement :meth:`_step` (one update from one estimate) and name their extra
    configuration and internal state in :meth:`_config` / :meth:`_internals`.
    """

    kind: ClassVar[str]

    def __init__(
        self,
        threshold: float,
        *,
        initial: float,
        max_value: float,
        schedule: Schedule,
        frozen: bool,
    ) -> None:
        self.threshold = _require_non_negative("threshold", threshold)
        self.initial = _require_non_negative("initial", initial)
        self.max_value = float(max_value)
        if math.isnan(self.max_value) or self.max_value < self.initial:
            raise ValueError(
                f"max_value must be >= initial ({self.initial}), got {self.max_value}"
            )
        if schedule not in _SCHEDULES:
            raise ValueError(f"schedule must be one of {_SCHEDULES}, got {schedule!r}")
        self.schedule: Schedule = schedule
        self.frozen = bool(frozen)
        self._value = self.initial
        self.num_updates = 0

    @property
    def value(self) -> float:
        """The current multiplier λ, always in [0, max_value]."""
        return self._value

    def update(self, estimates: Sequence[float] | float) -> float:
        """Updates λ from cost estimates Ĵ_C and returns the new value.

        Args:
            estimates: One estimate per finished episode, oldest first (or a single number).
                With schedule ``"episode"`` each one is a separate update, in order; with
                ``"batch"`` their mean is one update. An empty sequence changes nothing.

        Returns:
            The multiplier after the update (unchanged if ``frozen``).
        """
        values = _as_estimates(estimates)
        if self.frozen or not values:
            return self._value
        if self.schedule == "batch":
            values = [math.fsum(values) / len(values)]
        for estimate in values:
            self._step(estimate)
            self.num_updates += 1
        return self._value

    def _clip(self, value: float) -> float:
        return min(max(value, 0.0), self.max_value)

    @abc.abstractmethod
    def _step(self, estimate: float) -> None:
        """One update of ``self._value`` from one estimate."""

    def _config(self) -> dict[str, Any]:
        return {
            "threshold": self.threshold,
            "initial": self.initial,
            "max_value": self.max_value,
            "schedule": self.schedule,
            "frozen": self.frozen,
        }

    def _internals(self) -> dict[str, Any]:
        return {"value": self._value, "num_updates": self.num_updates}

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume: kind, configuration and internal state (plain Python)."""
        return {"kind": self.kind, "config": self._config(), "state": self._internals()}

    @classmethod
    def from_state_dict(cls, state_dict: Mapping[str, Any]) -> Self:
        """The multiplier saved by :meth:`state_dict`: its configuration and state.

        Raises:
            ValueError: if the state comes from another kind of multiplier or is invalid.
        """
        if state_dict.get("kind") != cls.kind:
            raise ValueError(
                f"cannot load a {state_dict.get('kind')!r} multiplier state into {cls.kind!r}"
            )
        multiplier = cls(**state_dict["config"])  # validates the configuration
        internals = dict(state_dict["state"])
        unknown = set(internals) - set(multiplier._internals())
        if unknown:
            raise ValueError(f"unknown multiplier state entries {sorted(unknown)}")
        multiplier._restore(internals)
        if not 0.0 <= multiplier._value <= multiplier.max_value:
            raise ValueError(f"value must lie in [0, {multiplier.max_value}], got "
                             f"{multiplier._value}")
        return multiplier

    def _restore(self, internals: Mapping[str, Any]) -> None:
        """Sets the entries of :meth:`_internals` that ``internals`` holds."""
        self._value = float(internals.get("value", self._value))
        self.num_updates = int(internals.get("num_updates", self.num_updates))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(value={self._value:.6g}, threshold={self.threshold:.6g})"


class LagrangeMultiplier(_Multiplier):
    """Projected dual ascent on one constraint J_C ≤ α.

    .. math::  λ ← \\mathrm{clip}(λ + η·(Ĵ_C − α),\\ 0,\\ λ_{max})

    Args:
        threshold: α, the constraint's limit, in the units of the estimates (>= 0).
        initial: λ before any update (>= 0).
        step_size: η > 0, the ascent step per update.
        max_value: λ_max >= initial (``math.inf`` for no upper bound).
        schedule: ``"episode"`` (one update per estimate) or ``"batch"`` (one per call, on the
            mean estimate).
        frozen: if ``True``, λ stays at ``initial`` whatever ``update`` receives.
    """

    kind = "dual"

    def __init__(
        self,
        threshold: float,
        *,
        initial: float = 0.0,
        step_size: float,
        max_value: float,
        schedule: Schedule = "episode",
        frozen: bool = False,
    ) -> None:
        super().__init__(
            threshold, initial=initial, max_value=max_value, schedule=schedule, frozen=frozen
        )
        self.step_size = _require_finite("step_size", step_size)
        if self.step_size <= 0.0:
            raise ValueError(f"step_size must be > 0, got {self.step_size}")

    def _step(self, estimate: float) -> None:
        self._value = self._clip(self._value + self.step_size * (estimate - self.threshold))

    def _config(self) -> dict[str, Any]:
        return {**super()._config(), "step_size": self.step_size}


class PIDLagrangeMultiplier(_Multiplier):
    """PID Lagrangian (Stooke et al. 2020, Algorithm 2) on one constraint J_C ≤ α.

    With optional exponential smoothing (EMA) of the violation and of the estimate::

        Δ   = Ĵ_C − α                          violation
        p   ← β_p·p + (1 − β_p)·Δ              smoothed violation (p = Δ when β_p = 0)
        I   ← clip(I + k_i·Δ, 0, λ_max)        integral, clipped at 0 (and at λ_max)
        s   ← β_d·s + (1 − β_d)·Ĵ_C            smoothed estimate
        D   = max(0, s − s_prev)               only an *increase* of the cost counts
        λ   = clip(k_p·p + I + k_d·D, 0, λ_max)

    The integral starts at ``initial``, so λ starts there; the EMAs start at their first
    input and D is 0 on the first update. The upper clip of the integral is anti-windup (the
    paper has no λ_max); with it, k_p = k_d = 0 is exactly dual ascent with η = k_i.

    Args:
        threshold: α (>= 0).
        initial: λ (and the integral) before any update (>= 0).
        kp: proportional gain (>= 0).
        ki: integral gain (> 0).
        kd: derivative gain (>= 0).
        max_value: λ_max >= initial.
        schedule: ``"episode"`` or ``"batch"``, as for :class:`LagrangeMultiplier`.
        ema_p: smoothing factor β_p in [0, 1); 0 disables smoothing.
        ema_d: smoothing factor β_d in [0, 1); 0 disables smoothing.
        frozen: if ``True``, λ stays at ``initial``.
    """

    kind = "pid"

    def __init__(
        self,
        threshold: float,
        *,
        initial: float = 0.0,
        kp: float,
        ki: float,
        kd: float,
        max_value: float,
        schedule: Schedule = "episode",
        ema_p: float = 0.0,
        ema_d: float = 0.0,
        frozen: bool = False,
    ) -> None:
        super().__init__(
            threshold, initial=initial, max_value=max_value, schedule=schedule, frozen=frozen
        )
        self.kp = _require_non_negative("kp", kp)
        self.ki = _require_non_negative("ki", ki)
        self.kd = _require_non_negative("kd", kd)
        if self.ki == 0.0:
            raise ValueError("ki must be > 0 (it plays the role of the step size)")
        for name, beta in (("ema_p", ema_p), ("ema_d", ema_d)):
            if not 0.0 <= float(beta) < 1.0:
                raise ValueError(f"{name} must lie in [0, 1), got {beta}")
        self.ema_p = float(ema_p)
        self.ema_d = float(ema_d)
        self.integral = self.initial
        self.smoothed_violation: float | None = None
        self.smoothed_estimate: float | None = None

    @staticmethod
    def _ema(previous: float | None, new: float, beta: float) -> float:
        return new if previous is None else beta * previous + (1.0 - beta) * new

    def _step(self, estimate: float) -> None:
        violation = estimate - self.threshold
        self.smoothed_violation = self._ema(self.smoothed_violation, violation, self.ema_p)
        self.integral = self._clip(self.integral + self.ki * violation)
        previous = self.smoothed_estimate
        self.smoothed_estimate = self._ema(previous, estimate, self.ema_d)
        rise = 0.0 if previous is None else max(0.0, self.smoothed_estimate - previous)
        self._value = self._clip(
            self.kp * self.smoothed_violation + self.integral + self.kd * rise
        )

    def _config(self) -> dict[str, Any]:
        return {
            **super()._config(),
            "kp": self.kp,
            "ki": self.ki,
            "kd": self.kd,
            "ema_p": self.ema_p,
            "ema_d": self.ema_d,
        }

    def _internals(self) -> dict[str, Any]:
        return {
            **super()._internals(),
            "integral": self.integral,
            "smoothed_violation": self.smoothed_violation,
            "smoothed_estimate": self.smoothed_estimate,
        }

    def _restore(self, internals: Mapping[str, Any]) -> None:
        super()._restore(internals)
        self.integral = float(internals.get("integral", self.integral))
        self.smoothed_violation = internals.get("smoothed_violation", self.smoothed_violation)
        self.smoothed_estimate = internals.get("smoothed_estimate", self.smoothed_estimate)


Multiplier = LagrangeMultiplier | PIDLagrangeMultiplier

_KINDS: dict[str, type[_Multiplier]] = {
    LagrangeMultiplier.kind: LagrangeMultiplier,
    PIDLagrangeMultiplier.kind: PIDLagrangeMultiplier,
}


def make_multiplier(kind: MultiplierKind, **kwargs: Any) -> Multiplier:
    """Builds a multiplier by kind: ``"dual"`` (:class:`LagrangeMultiplier`) or ``"pid"``.

    Args:
        kind: Which update rule.
        **kwargs: The chosen class's constructor arguments (``threshold`` included).

    Raises:
        ValueError: for an unknown kind or invalid arguments.
    """
    if kind not in _KINDS:
        raise ValueError(f"unknown multiplier kind {kind!r}; expected one of {sorted(_KINDS)}")
    try:
        return _KINDS[kind](**kwargs)  # type: ignore[return-value]
    except TypeError as err:  # missing or unexpected keyword: report it as a config error
        raise ValueError(f"bad arguments for a {kind!r} multiplier: {err}") from err


def multiplier_from_state(state_dict: Mapping[str, Any]) -> Multiplier:
    """The multiplier saved by ``state_dict()``, of the kind it names."""
    kind = state_dict.get("kind")
    if kind not in _KINDS:
        raise ValueError(f"unknown multiplier kind {kind!r}; expected one of {sorted(_KINDS)}")
    return _KINDS[kind].from_state_dict(state_dict)  # type: ignore[return-value]
