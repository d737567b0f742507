"""Runs a peer library trained on a crllk task (``peers/omnisafe/train.py``), evaluated exactly as
crllk's own: the same simulations, spawn seeds, episodes and metrics, written in the same
``<name>.json`` document.

A peer run directory holds ``peer.json`` (library, algorithm, task, seed, frames, wall time,
and a probe: the library's own deterministic actions for fixed observations), ``policy.npz``
(:mod:`crllk.rl.peer_policy`) and ``episodes.csv`` (every training episode, in
``metrics.csv``'s columns). Loading checks the probe: the policy crllk plays is the one the
library trained, to 1e-4.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from crllk.config import algo_thresholds
from crllk.envs.batched import make_env
from crllk.errors import ConfigError
from crllk.evaluation import community
from crllk.evaluation.report import result_document
from crllk.evaluation.runs import EVALUATION_ENVS, result_path
from crllk.files import atomic_write_text, output_lock
from crllk.rl.peer_policy import load_peer_policy
from crllk.rl.rollout import run_episodes

PEER_FILE, PEER_POLICY, PEER_EPISODES = "peer.json", "policy.npz", "episodes.csv"
PROBE_TOLERANCE = 1e-4
"""Largest difference allowed between the library's probe actions and crllk's."""


def read_peer(run_dir: str | Path) -> dict[str, Any]:
    """``peer.json`` of a peer run.

    Raises:
        ConfigError: naming the file, if it is missing or not a peer description.
    """
    path = Path(run_dir) / PEER_FILE
    try:
        document = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ConfigError(path, "peer", f"cannot be read ({err})") from None
    if not isinstance(document, dict):
        raise ConfigError(path, "peer", "expected a JSON object")
    missing = [k for k in ("library", "algo", "task", "seed", "frames") if k not in document]
    if missing:
        raise ConfigError(path, "peer", f"missing {', '.join(missing)}")
    return document


def load_peer_actor(run_dir: str | Path, observation_size: int, action_size: int):
    """The run's policy, checked against the library's probe actions.

    Raises:
        ConfigError: for a policy that does not reproduce them.
    """
    peer = read_peer(run_dir)
    actor = load_peer_policy(Path(run_dir) / PEER_POLICY, observation_size=observation_size,
                             action_size=action_size, activation=peer.get("activation", "tanh"))
    probe = peer.get("probe")
    if probe:
        try:
            states = torch.as_tensor(probe["states"], dtype=torch.float32)
            expected = torch.as_tensor(probe["actions"], dtype=torch.float32)
            with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
                actions = actor(TensorDict({"state": states}, batch_size=[len(states)]))
            gap = float((actions["action"] - expected).abs().max())
        except (KeyError, TypeError, ValueError, RuntimeError) as err:
            raise ConfigError(Path(run_dir) / PEER_FILE, "probe", f"unusable: "
                              f"{' '.join(str(err).split())[:120]}") from None
        if gap > PROBE_TOLERANCE:
            raise ConfigError(Path(run_dir) / PEER_POLICY, "policy", f"plays actions {gap:.2g} "
                              f"from the library's own on its probe")
    return actor, peer


def evaluate_peer(run_dir: str | Path, *, episodes: int, seed: int,
                  deterministic: bool = False, name: str | None = None,
                  num_envs: int = EVALUATION_ENVS) -> dict[str, Any]:
    """Plays the peer run's policy (sampled, or its mean with ``deterministic``) as
    :func:`crllk.evaluation.runs.evaluate_run` plays a crllk run, and writes ``<name>.json``."""
    run_dir = Path(run_dir)
    peer = read_peer(run_dir)
    thresholds = algo_thresholds()
    with output_lock(result_path(run_dir, name)):
        env = make_env(peer["task"], num_envs=num_envs, observation="state",
                       action="continuous", seed=seed, lane_pose=True)
        try:
            size = int(env.observation_spec["state"].shape[-1])
            actor, _ = load_peer_actor(run_dir, size, int(env.action_spec.shape[-1]))
            result = run_episodes(env, actor, episodes, deterministic=deterministic,
                                  sample_seed=seed)
        finally:
            env.close()
        thresholds = {c.name: thresholds[c.name] for c in env.config.constraints}
        document = result_document(
            result, "continuous", thresholds=thresholds,
            settings={"episodes": episodes, "seed": seed, "num_envs": num_envs,
                      "deterministic": deterministic},
            source={"run_dir": str(run_dir), "task": peer["task"],
                    "algo": f"{peer['library']}-{peer['algo']}", "action": "continuous",
                    "obs": "state", "train_seed": peer["seed"], "frames": peer["frames"],
                    "elapsed": peer.get("wall_s")},
            objects=env.config.map.objects, scales=community.Scales.of(env.config))
        atomic_write_text(result_path(run_dir, name), json.dumps(document, indent=1) + "\n")
    return document


__all__ = ["PEER_EPISODES", "PEER_FILE", "PEER_POLICY", "evaluate_peer", "load_peer_actor",
           "read_peer"]
