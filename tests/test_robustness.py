"""The held-out perturbations of robustness evaluations: valid task settings, beyond the
ranges randomised training draws from, and each one changing what the policy meets."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import crllk
from crllk.evaluation.robustness import HELD_OUT, conditions, result_name
from crllk.tasks.config import load_task_config
from crllk.tasks.randomization import PRESETS


def test_every_condition_is_a_valid_change_of_task_settings():
    table = conditions()
    assert list(table) == ["nominal", *HELD_OUT, "deployment", "combined"]
    for name, overrides in table.items():
        config = load_task_config("small_loop", overrides)
        assert (config.randomize is not None) == ("randomize" in overrides), name
        assert result_name(name).startswith("robust-") and " " not in result_name(name)


@pytest.mark.parametrize("axis", list(HELD_OUT))
def test_held_out_ranges_lie_beyond_the_training_ranges(axis):
    trained = PRESETS["default"]
    for field, held_out in HELD_OUT[axis].items():
        training = getattr(trained, field)
        if isinstance(held_out, int | float):  # a std, a half-width or a count
            assert held_out > training, field
            continue
        low, high = held_out
        assert high <= training[0] + 1e-9 or low >= training[1] - 1e-9, field


def test_each_appearance_condition_changes_the_image():
    def first_image(overrides):
        env = crllk.load("small_loop", observation="pixels", seed=4, overrides=overrides)
        return env.reset().observation["pixels"].astype(int)

    nominal = first_image({})
    for name in ("lighting", "colours", "camera pose", "deployment"):
        assert np.abs(first_image(conditions()[name]) - nominal).mean() > 1.0, name


def test_randomize_fields_exist():
    names = {f.name for f in dataclasses.fields(PRESETS["default"])}
    for ranges in HELD_OUT.values():
        assert set(ranges) <= names
