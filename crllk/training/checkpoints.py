"""Checkpoints of training runs, written atomically and stamped with a format version.

A checkpoint or kept policy holds tensors and plain containers only (:mod:`crllk.rl.plain`)
and is read with ``torch.load(weights_only=True)``, so that reading a file cannot run code; a
file that needs more (a checkpoint of an older format, or one crafted to run code) is refused,
and ``python -m crllk.convert`` converts one the user trusts (:mod:`crllk.convert`).
"""

from __future__ import annotations

import pickle
import re
import shlex
from pathlib import Path
from typing import Any

import torch
from omegaconf import OmegaConf
from tensordict import TensorDictBase

from crllk.config import TrainConfig
from crllk.envs.episodes import EpisodeAccumulator
from crllk.errors import ConfigError
from crllk.files import atomic_write
from crllk.rl.lagrange import Multiplier, multiplier_from_state
from crllk.rl.plain import first_non_plain, tensordict_from_plain, tensordict_to_plain
from crllk.training.build import Learner, TrainingEnv, keeps_snapshots

CHECKPOINT_FORMAT = 5
"""Version of the checkpoint layout written by :mod:`crllk.training.loop` (2: constraints by
name, the task's episode state whole; 3: each simulation's action stream; 4: format 3 in
tensors and plain containers only, read without running code; 5: the batch collected ahead,
``ahead``, with the simulations one batch past the episode sums when there is one)."""
READABLE_FORMATS = (2, 3, 4, 5)
"""Formats whose policy (actor, counters, multipliers) this version reads, from a file that
loads without running code (every kept ``policy.pt``; checkpoints of formats 2 and 3 once
converted); only :data:`RESUMABLE_FORMATS` resume."""
RESUMABLE_FORMATS = (4, 5)
"""Formats a run resumes from: format 4 is format 5 without a batch collected ahead."""
CONVERTED_FORMATS = {3: 4}
"""The format a checkpoint of an older one takes once converted to plain types
(:func:`crllk.convert.convert_file`), where the newer format is the older one in plain types;
other formats keep their number."""
CONVERT_COMMAND = "python -m crllk.convert"


class UnsafeFileError(ConfigError):
    """A file that only a full unpickling reads, which may run code: refused."""


def save_checkpoint(path: str | Path, state: dict[str, Any]) -> Path:
    """Saves ``state`` with ``torch.save`` atomically, stamped with the format version."""
    return write_state(path, {"format": CHECKPOINT_FORMAT, **state})


def write_state(path: str | Path, state: dict[str, Any]) -> Path:
    """Writes a checkpoint's ``state`` (format included) atomically.

    Raises:
        TypeError: if ``state`` holds anything but tensors and plain containers (it would
            not load without running code).
    """
    problem = first_non_plain(state)
    if problem:
        raise TypeError(f"checkpoint {path}: only tensors and plain containers are saved, "
                        f"got {problem}")
    return atomic_write(path, lambda handle: torch.save(state, handle))


def read_state(path: str | Path, *, trust: bool = False) -> object:
    """What ``torch.save`` wrote to ``path``, read with ``weights_only=True``; only with
    ``trust`` by a full unpickling, which runs whatever code the file names.

    Raises:
        UnsafeFileError: without ``trust``, if the file holds more than tensors and plain
            containers.
        ConfigError: if the file cannot be read or is damaged.
    """
    path = Path(path)
    try:
        if not _looks_saved_by_torch(path):
            raise ConfigError(path, "<file>", "not a checkpoint: neither the zip archive "
                              "torch.save writes nor a pickle")
        return torch.load(path, map_location="cpu", weights_only=not trust)
    except ConfigError:
        raise
    except OSError as err:
        raise ConfigError(path, "<file>", f"cannot read: {err.strerror or err}") from None
    except pickle.UnpicklingError as err:
        if trust:
            raise ConfigError(path, "<file>", f"not a readable checkpoint: {_first_line(err)}"
                              ) from None
        named = re.search(r"GLOBAL ([\w.]+)", str(err))
        raise UnsafeFileError(path, "<file>", (
            f"holds pickled Python objects{f' ({named[1]})' if named else ''}, and loading "
            "them may execute code: refused. An older checkpoint you trust converts with "
            f"{CONVERT_COMMAND} path={shlex.quote(str(path))} trust=true")) from None
    except Exception as err:  # torch raises RuntimeError, pickle errors, EOFError...
        raise ConfigError(path, "<file>", f"not a readable checkpoint (damaged or truncated: "
                          f"{_first_line(err)})") from None


def _looks_saved_by_torch(path: Path) -> bool:
    """Whether the file starts as a format ``torch.save`` writes does (damaged or not): its zip
    archive (a local file header), or a pickle (the protocol byte 0x80)."""
    with path.open("rb") as handle:
        start = handle.read(4)
    return start == b"PK\x03\x04" or start[:1] == b"\x80"


def _first_line(err: BaseException) -> str:
    return str(err).splitlines()[0] if str(err) else type(err).__name__


POLICY_FILE = Path("policy.pt")
"""A run's kept policy, beside ``config.yaml``: written with every checkpoint, and kept where
the checkpoints are not (``results/runs``)."""
POLICY_KEYS = ("iteration", "frames", "elapsed", "actor", "multipliers")
"""What a run's kept policy file holds: enough to act, evaluate and export, not to resume."""


def policy_state(state: dict[str, Any]) -> dict[str, Any]:
    """The part of a checkpoint's ``state`` that :data:`POLICY_KEYS` names (a few hundred kB
    where the whole checkpoint, optimiser and simulations included, is many MB)."""
    return {key: state[key] for key in POLICY_KEYS}


def policy_info(state: dict[str, Any]) -> dict[str, Any]:
    """A checkpoint's (or kept policy's) counters and multiplier values: ``iteration``,
    ``frames``, ``elapsed_s`` and ``multipliers`` (by constraint name)."""
    return {"iteration": int(state["iteration"]), "frames": int(state["frames"]),
            "elapsed_s": float(state["elapsed"]),
            "multipliers": {name: float(m["state"]["value"])
                            for name, m in state["multipliers"].items()}}


def load_checkpoint(path: str | Path, *, resuming: bool = False) -> dict[str, Any]:
    """Loads a checkpoint written by :func:`save_checkpoint` (of any of
    :data:`READABLE_FORMATS`; only of :data:`RESUMABLE_FORMATS` when ``resuming``)."""
    state = read_state(path)
    check_format(path, state, resuming=resuming)
    return state  # type: ignore[return-value]


def check_format(path: str | Path, state: object, *, resuming: bool = False) -> None:
    """Refuses ``state`` unless it is a checkpoint of :data:`READABLE_FORMATS` (only
    :data:`RESUMABLE_FORMATS` when ``resuming``).

    Raises:
        ConfigError: naming ``path`` and the format.
    """
    if not isinstance(state, dict) or "format" not in state:
        raise ConfigError(path, "format", "not a crllk checkpoint")
    readable = RESUMABLE_FORMATS if resuming else READABLE_FORMATS
    if state["format"] not in readable:
        raise ConfigError(path, "format", f"written in format {state['format']}, this version "
                          f"{'resumes' if resuming else 'reads'} format "
                          f"{' and '.join(map(str, readable))}: resume it with the version "
                          "that wrote it, or start a new run")


def checkpoint_state(config: TrainConfig, learner: Learner, multipliers: dict[str, Multiplier],
                     episodes: EpisodeAccumulator, env: TrainingEnv,
                     generator: torch.Generator, carry: TensorDictBase | None, *, iteration: int,
                     frames: int, elapsed: float, ahead: TensorDictBase | None = None
                     ) -> dict[str, Any]:
    """What :func:`restore` needs; ``env``, ``carry`` and the running episode sums are None
    when the simulations' state is not kept (remote collectors). ``ahead``: the batch
    collected ahead and not yet learned from (``collect_ahead``; the simulations, ``carry``
    and the action streams as its collection left them)."""
    snapshots = keeps_snapshots(env)
    return {
        "iteration": iteration, "frames": frames, "elapsed": elapsed,
        "config": OmegaConf.to_container(OmegaConf.structured(config)),
        **learner.state_dict(),
        "multipliers": {name: m.state_dict() for name, m in multipliers.items()},
        "episodes": episodes.state_dict() if snapshots else None,
        "env": env.sim_state() if snapshots else None,
        "carry": tensordict_to_plain(carry.clone()) if snapshots else None,
        "ahead": tensordict_to_plain(ahead.clone()) if snapshots and ahead is not None else None,
        "torch_rng": torch.get_rng_state(),
        "generator": generator.get_state(),
        "action_noise": learner.action_noise.states(),
    }


def restore(state: dict[str, Any], learner: Learner, multipliers: dict[str, Multiplier],
            episodes: EpisodeAccumulator, env: TrainingEnv, generator: torch.Generator) -> bool:
    """Loads a checkpoint into the run's parts. Returns whether the simulations continue
    exactly where they were (their state and the running episode sums restored, and
    :func:`resumed_carry` to continue from); if the checkpoint has no simulations' state or
    ``env`` cannot take one (remote collectors), episodes start afresh."""
    learner.load_state_dict(state)
    for name in multipliers:
        multipliers[name] = multiplier_from_state(state["multipliers"][name])
    exact = state["env"] is not None and keeps_snapshots(env)
    if exact:
        episodes.load_state_dict(state["episodes"])
        env.load_sim_state(state["env"])
    torch.set_rng_state(state["torch_rng"])
    generator.set_state(state["generator"])
    learner.action_noise.load_states(state["action_noise"])
    return exact


def resumed_carry(state: dict[str, Any]) -> TensorDictBase:
    """The tensordict collection continues from, as :func:`checkpoint_state` kept it."""
    return tensordict_from_plain(state["carry"])


def resumed_ahead(state: dict[str, Any]) -> TensorDictBase | None:
    """The batch collected ahead that :func:`checkpoint_state` kept, learned from first (None:
    none was; checkpoints written before ``collect_ahead`` have none)."""
    ahead = state.get("ahead")
    return None if ahead is None else tensordict_from_plain(ahead)
