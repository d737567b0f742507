"""Numeric unit tests of the Lagrange multipliers, with the arithmetic worked out in comments."""

from __future__ import annotations

import copy
import math

import pytest
import torch

from crllk.rl.lagrange import (
    LagrangeMultiplier,
    PIDLagrangeMultiplier,
    make_multiplier,
    multiplier_from_state,
)


def _dual(**overrides: object) -> LagrangeMultiplier:
    kwargs = {"threshold": 0.5, "step_size": 0.1, "max_value": 10.0} | overrides
    return LagrangeMultiplier(**kwargs)


def _pid(**overrides: object) -> PIDLagrangeMultiplier:
    kwargs = {"threshold": 0.5, "kp": 0.5, "ki": 0.1, "kd": 0.0, "max_value": 10.0} | overrides
    return PIDLagrangeMultiplier(**kwargs)


# ------------------------------------------------------------------------------ dual ascent


def test_rises_while_the_constraint_is_violated():
    # λ = 0 + η·(Ĵ − α) = 0 + 0.1·(1.5 − 0.5) = 0.1
    multiplier = _dual()
    assert multiplier.update([1.5]) == pytest.approx(0.1)
    # and again: 0.1 + 0.1·1.0 = 0.2
    assert multiplier.update(1.5) == pytest.approx(0.2)
    assert multiplier.value == pytest.approx(0.2)


def test_falls_while_the_constraint_holds():
    # λ = 1.0 + 0.1·(0.0 − 0.5) = 0.95
    assert _dual(initial=1.0).update([0.0]) == pytest.approx(0.95)


def test_never_negative():
    # 0.02 + 0.1·(0.0 − 0.5) = −0.03 → clipped to 0
    multiplier = _dual(initial=0.02)
    assert multiplier.update([0.0]) == 0.0
    assert multiplier.update([0.0, 0.0, 0.0]) == 0.0


def test_clipped_at_max_value():
    # 0.9 + 0.1·(3.0 − 0.5) = 1.15 → clipped to λ_max = 1.0
    assert _dual(initial=0.9, max_value=1.0).update([3.0]) == 1.0


def test_episode_and_batch_schedules_differ_as_computed():
    # estimates (0.0, 2.0), α = 0.5, η = 1, λ = 0
    # episode: 0 + (0.0 − 0.5) = −0.5 → 0, then 0 + (2.0 − 0.5) = 1.5
    # batch:   mean = 1.0, 0 + (1.0 − 0.5) = 0.5
    episode = _dual(step_size=1.0, schedule="episode")
    batch = _dual(step_size=1.0, schedule="batch")
    assert episode.update([0.0, 2.0]) == pytest.approx(1.5)
    assert batch.update([0.0, 2.0]) == pytest.approx(0.5)
    assert (episode.num_updates, batch.num_updates) == (2, 1)


def test_empty_update_changes_nothing():
    multiplier = _dual(initial=0.3)
    assert multiplier.update([]) == 0.3
    assert multiplier.num_updates == 0


def test_accepts_tensors():
    # 0 + 0.1·(1.5 − 0.5) + 0.1·(2.5 − 0.5) = 0.1 + 0.2 = 0.3
    assert _dual().update(torch.tensor([1.5, 2.5])) == pytest.approx(0.3)
    # a 0-d tensor is one estimate: 0 + 0.1·(1.5 − 0.5) = 0.1
    assert _dual().update(torch.tensor(1.5)) == pytest.approx(0.1)


@pytest.mark.parametrize("factory", [_dual, _pid])
def test_frozen_stays_fixed(factory):
    multiplier = factory(initial=1.0, frozen=True)
    assert multiplier.update([100.0, 0.0, 7.0]) == 1.0
    assert multiplier.value == 1.0
    assert multiplier.num_updates == 0


def test_dual_state_round_trips():
    source = _dual(initial=0.2, schedule="batch")
    source.update([1.5, 2.5])  # 0.2 + 0.1·(2.0 − 0.5) = 0.35
    target = LagrangeMultiplier.from_state_dict(copy.deepcopy(source.state_dict()))
    assert target.state_dict() == source.state_dict()
    assert target.value == pytest.approx(0.35)
    # both continue identically: 0.35 + 0.1·(1.0 − 0.5) = 0.40
    assert target.update([1.0, 1.0]) == source.update([1.0, 1.0]) == pytest.approx(0.40)


def test_pid_state_round_trips_including_internals():
    source = _pid(kd=1.0, ema_p=0.5, ema_d=0.25)
    source.update([1.0, 2.0, 0.7])
    state = source.state_dict()
    assert {"integral", "smoothed_violation", "smoothed_estimate"} <= set(state["state"])
    target = multiplier_from_state(copy.deepcopy(state))
    assert target.state_dict() == state
    assert target.integral == source.integral
    assert target.smoothed_estimate == source.smoothed_estimate
    for estimates in ([3.0], [0.0, 0.1], [2.0]):
        assert target.update(estimates) == source.update(estimates)


def test_loading_another_kind_raises():
    with pytest.raises(ValueError, match="'pid'"):
        LagrangeMultiplier.from_state_dict(_pid().state_dict())
    with pytest.raises(ValueError, match="unknown multiplier kind 'lbfgs'"):
        multiplier_from_state({**_pid().state_dict(), "kind": "lbfgs"})


# ---------------------------------------------------------------------------------------- PID


def test_pid_reacts_to_a_sustained_violation_faster_than_dual_ascent():
    # Ĵ = 1.5 every episode, α = 0.5, so Δ = 1.0.
    # dual, η = 0.1:        λ = 0.1, 0.2, 0.3
    # PID, k_i = η, k_p = 0.5: I = 0.1, 0.2, 0.3 and λ = 0.5·1.0 + I = 0.6, 0.7, 0.8
    dual, pid = _dual(), _pid()
    dual_values = [dual.update([1.5]) for _ in range(3)]
    pid_values = [pid.update([1.5]) for _ in range(3)]
    assert dual_values == pytest.approx([0.1, 0.2, 0.3])
    assert pid_values == pytest.approx([0.6, 0.7, 0.8])
    assert all(p > d for p, d in zip(pid_values, dual_values, strict=True))


def test_pid_derivative_acts_only_on_an_increase_of_the_cost():
    # k_p = 0, k_i = 0.1, k_d = 1, α = 0.5
    # Ĵ = 1.0: I = 0.1·0.5 = 0.05, D = 0 (first update)         → λ = 0.05
    # Ĵ = 1.5: I = 0.05 + 0.1·1.0 = 0.15, D = 1.5 − 1.0 = 0.5    → λ = 0.65
    # Ĵ = 1.0: I = 0.15 + 0.05 = 0.20, D = max(0, −0.5) = 0      → λ = 0.20
    pid = _pid(kp=0.0, kd=1.0)
    assert [pid.update([j]) for j in (1.0, 1.5, 1.0)] == pytest.approx([0.05, 0.65, 0.20])


def test_pid_integral_is_clipped_at_zero():
    # k_p = k_d = 0, k_i = 0.1, α = 0.5
    # Ĵ = 0: I = max(0, 0 − 0.05) = 0, twice; Ĵ = 1.5: I = 0 + 0.1 = 0.1 (not −0.1 + 0.1 = 0)
    pid = _pid(kp=0.0)
    assert [pid.update([j]) for j in (0.0, 0.0, 1.5)] == pytest.approx([0.0, 0.0, 0.1])
    assert pid.integral == pytest.approx(0.1)


def test_pid_with_only_an_integral_gain_is_dual_ascent():
    # Including after saturation: at 2.2 both reach 0.47 → 0.4; at 0.0 both fall to 0.35
    # (the integral is clipped at λ_max too, so it does not wind up to 0.47).
    estimates = [1.5, 0.0, 0.0, 0.9, 3.0, 0.2, 0.4, 2.2, 0.0]
    dual = _dual(initial=0.05, max_value=0.4)
    pid = _pid(initial=0.05, max_value=0.4, kp=0.0)
    for estimate in estimates:
        assert pid.update([estimate]) == pytest.approx(dual.update([estimate]))


def test_pid_ema_smooths_the_proportional_term():
    # k_p = 1, k_i = 0.1, β_p = 0.5, α = 0.5
    # Ĵ = 1.5: Δ = 1.0, p = 1.0 (first input), I = 0.1 → λ = 1.1
    # Ĵ = 0.5: Δ = 0.0, p = 0.5·1.0 + 0.5·0.0 = 0.5, I = 0.1 → λ = 0.6 (0.1 without the EMA)
    smoothed, raw = _pid(kp=1.0, ema_p=0.5), _pid(kp=1.0)
    assert [smoothed.update([j]) for j in (1.5, 0.5)] == pytest.approx([1.1, 0.6])
    assert [raw.update([j]) for j in (1.5, 0.5)] == pytest.approx([1.1, 0.1])


# ------------------------------------------------------------------------- factory, arguments


def test_factory_builds_both_kinds():
    dual = make_multiplier("dual", threshold=0.5, step_size=0.1, max_value=5.0)
    pid = make_multiplier("pid", threshold=0.5, kp=1.0, ki=0.1, kd=0.0, max_value=5.0)
    assert isinstance(dual, LagrangeMultiplier)
    assert isinstance(pid, PIDLagrangeMultiplier)
    assert make_multiplier("dual", threshold=0.0, step_size=1.0, max_value=math.inf).update(
        [1e6]
    ) == pytest.approx(1e6)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"threshold": -0.1}, "threshold must be >= 0"),
        ({"threshold": math.nan}, "threshold must be a finite number"),
        ({"step_size": 0.0}, "step_size must be > 0"),
        ({"step_size": -1e-3}, "step_size must be > 0"),
        ({"initial": -1.0}, "initial must be >= 0"),
        ({"initial": 2.0, "max_value": 1.0}, "max_value must be >= initial"),
        ({"schedule": "step"}, "schedule must be one of"),
    ],
)
def test_bad_dual_arguments_raise(kwargs, message):
    with pytest.raises(ValueError, match=message):
        _dual(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"ki": 0.0}, "ki must be > 0"),
        ({"kp": -1.0}, "kp must be >= 0"),
        ({"ema_p": 1.0}, "ema_p must lie in"),
        ({"ema_d": -0.1}, "ema_d must lie in"),
    ],
)
def test_bad_pid_arguments_raise(kwargs, message):
    with pytest.raises(ValueError, match=message):
        _pid(**kwargs)


def test_bad_factory_calls_and_estimates_raise():
    with pytest.raises(ValueError, match="unknown multiplier kind"):
        make_multiplier("adam", threshold=0.5)
    with pytest.raises(ValueError, match="bad arguments for a 'dual' multiplier"):
        make_multiplier("dual", threshold=0.5, max_value=1.0)  # no step_size
    with pytest.raises(ValueError, match="cost estimate must be a finite number"):
        _dual().update([1.0, math.nan])
