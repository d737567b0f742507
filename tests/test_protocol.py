"""The test protocol: the test seed appears in no training or validation configuration, and
every command that trains or validates refuses it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from crllk.config import validate
from crllk.errors import ConfigError
from crllk.experiments.runs import Settings
from crllk.protocol import TEST_EPISODES, TEST_SEED, VALIDATION_EPISODES, VALIDATION_SEED
from crllk.training.compose import compose_config

REPO = Path(__file__).resolve().parents[1]
SEED_TEXTS = (str(TEST_SEED), f"{TEST_SEED:_}", f"{TEST_SEED:,}")


def _tracked(*patterns: str) -> list[Path]:
    listed = subprocess.run(["git", "ls-files", *patterns], cwd=REPO, capture_output=True,
                            text=True, check=True).stdout.split()
    return [REPO / name for name in listed]


def test_the_seeds_are_apart():
    assert TEST_SEED != VALIDATION_SEED
    assert TEST_EPISODES >= 400 and VALIDATION_EPISODES == 100
    assert Settings().eval_seed == TEST_SEED and Settings().episodes == TEST_EPISODES
    assert validate(compose_config([])).eval.seed == VALIDATION_SEED


@pytest.mark.parametrize("override", [f"seed={TEST_SEED}", f"eval.seed={TEST_SEED}"])
def test_the_trainer_refuses_the_test_seed(override):
    with pytest.raises(ConfigError, match="must not be the test seed"):
        validate(compose_config([override]))


def test_evaluate_refuses_the_test_seed():
    completed = subprocess.run(
        [sys.executable, "-m", "crllk.evaluate", "follower=true", "task=small_loop",
         "episodes=1", f"seed={TEST_SEED}"], cwd=REPO, capture_output=True, text=True,
        timeout=120)
    assert completed.returncode == 2
    assert completed.stderr.strip() == (
        "error: evaluate: seed: must not be the test seed, which only the table experiments "
        f"evaluate on (python -m crllk.experiments), got {TEST_SEED}")


def test_no_training_or_validation_configuration_holds_the_test_seed():
    """Trainer groups, task files, committed runs' configurations and validation curves,
    scripts, notebooks and examples: none of them names the test seed; in the package only
    the protocol module does."""
    configurations = _tracked("*.yaml", "*.yml", "eval.csv", "*.ipynb", "*.sh", "Makefile",
                              "examples/*", "scripts/*", "crllk/*.py", "tests/conftest.py")
    assert len(configurations) > 100
    for path in configurations:
        if path == REPO / "crllk/protocol.py":
            continue
        text = path.read_text(errors="replace")
        assert not any(seed in text for seed in SEED_TEXTS), path
    runs = _tracked("results/runs/**/config.yaml")
    assert runs
    for path in runs:
        config = OmegaConf.load(path)
        assert config.seed != TEST_SEED and config.eval.seed != TEST_SEED, path
