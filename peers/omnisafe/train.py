"""Trains an OmniSafe agent (PPOLag, CPPOPID, ...) on a crllk task, in OmniSafe's own Python.

    .venv-omnisafe/bin/python peers/omnisafe/train.py --algo PPOLag --task small_loop \
        --seed 0 --frames 300000 --run-dir results/runs/state/small_loop/OmniSafe-PPOLag-a0.5-seed0

(``make peers`` builds ``.venv-omnisafe`` from ``peers/omnisafe/requirements.txt``.) OmniSafe
0.5 needs Python 3.10 and its own pins, so this file imports nothing of crllk: the task runs in
crllk's Python (``python -m crllk.peers.env_server``, ``--crllk-python``), spoken to over a
pipe in JSON lines, and gives OmniSafe its one cost (``crllk.peers.env_server.scalar_cost``,
limit 1). Every training episode lands in ``<run_dir>/episodes.csv`` (written by the server).

At the end the policy goes to ``<run_dir>/policy.npz`` (arrays only: the observation
normaliser, the actor's layers and log standard deviation) and ``<run_dir>/peer.json`` (the
algorithm, its settings, frames and wall time), which crllk's evaluation reads
(``crllk.rl.peer_policy``). OmniSafe's own logs go to ``<run_dir>/omnisafe/``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import omnisafe
import torch
from gymnasium import spaces
from omnisafe.envs.core import CMDP, env_register

ROOT = Path(__file__).resolve().parents[2]
"""The crllk checkout this file belongs to."""


class TaskServer:
    """A ``crllk.peers.env_server`` process and its pipe."""

    def __init__(self, python: str, task: str, log: Path):
        self.process = subprocess.Popen(
            [python, "-m", "crllk.peers.env_server", f"task={task}", f"log={log}"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT,
            env={**os.environ, "OMP_NUM_THREADS": "1"})
        self.description = self._read()

    def ask(self, request: dict[str, Any]) -> dict[str, Any]:
        self.process.stdin.write(json.dumps(request) + "\n")
        self.process.stdin.flush()
        return self._read()

    def _read(self) -> dict[str, Any]:
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError(f"the task server ended (status {self.process.wait()})")
        reply = json.loads(line)
        if "error" in reply:
            raise RuntimeError(f"the task server: {reply['error']}")
        return reply

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.stdin.write(json.dumps({"close": True}) + "\n")
            self.process.stdin.close()
            self.process.wait(timeout=60)


def task_environment(python: str, task: str, log: Path, description: dict[str, Any]) -> type:
    """An OmniSafe environment class serving ``task`` (id ``crllk/<task>``), registered."""

    class CrllkTask(CMDP):
        """The crllk task, its server started at the first reset (OmniSafe also builds an
        evaluation environment it never steps here)."""

        _support_envs: ClassVar[list[str]] = [f"crllk/{task}"]
        need_auto_reset_wrapper = True
        need_time_limit_wrapper = False  # the task truncates at its own horizon
        _num_envs = 1

        def __init__(self, env_id: str, **kwargs: Any) -> None:
            self._device = kwargs.get("device", "cpu")
            size = description["observation_size"]
            self._observation_space = spaces.Box(-np.inf, np.inf, (size,), np.float32)
            self._action_space = spaces.Box(-1.0, 1.0, (description["action_size"],),
                                            np.float32)
            self._server: TaskServer | None = None
            self._seed: int | None = None
            self.env_spec_log: dict[str, Any] = {}

        @property
        def max_episode_steps(self) -> int:
            return description["horizon"]

        def _tensor(self, value: Any, dtype: torch.dtype = torch.float32) -> torch.Tensor:
            return torch.as_tensor(value, dtype=dtype, device=self._device)

        def step(self, action: torch.Tensor):
            assert self._server is not None, "step before reset"
            reply = self._server.ask({"step": action.detach().cpu().reshape(-1).tolist()})
            observation = self._tensor(reply["observation"])
            # no "final_observation" here: OmniSafe's AutoReset adds it (a separate tensor) when
            # an episode ends, and its ObsNormalize normalises that entry in place: the same
            # tensor as the observation would be normalised twice
            return (observation, self._tensor(reply["reward"]), self._tensor(reply["cost"]),
                    self._tensor(reply["terminated"], torch.bool),
                    self._tensor(reply["truncated"], torch.bool), {})

        def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
            if self._server is None:
                self._server = TaskServer(python, task, log)
            if seed is not None:
                self._seed = seed
            reply = self._server.ask({"reset": self._seed})
            self._seed = None  # the spawn stream goes on from the first seed
            return self._tensor(reply["observation"]), {}

        def single_reset(self, idx: int, seed: int | None = None):
            return self.reset(seed)

        def set_seed(self, seed: int) -> None:
            self._seed = int(seed)

        def sample_action(self) -> torch.Tensor:
            return self._tensor(self._action_space.sample())

        def spec_log(self, logger: Any) -> None:
            """Nothing beyond OmniSafe's own episode statistics."""

        def render(self) -> Any:
            return None

        def close(self) -> None:
            if self._server is not None:
                self._server.close()
                self._server = None

    env_register(CrllkTask)
    return CrllkTask


def policy_arrays(agent: Any) -> dict[str, np.ndarray]:
    """The trained actor and observation normaliser as named arrays."""
    algo = agent.agent
    actor = algo._actor_critic.actor
    arrays: dict[str, np.ndarray] = {"log_std": actor.log_std.detach().numpy()}
    layers = [m for m in actor.mean if isinstance(m, torch.nn.Linear)]
    for k, layer in enumerate(layers):
        arrays[f"layer{k}.weight"] = layer.weight.detach().numpy()
        arrays[f"layer{k}.bias"] = layer.bias.detach().numpy()
    normaliser = algo._env.save().get("obs_normalizer")
    if normaliser is not None:
        arrays["obs_mean"] = normaliser.mean.detach().numpy()
        arrays["obs_std"] = normaliser.std.detach().numpy()
        arrays["obs_clip"] = normaliser._clip.detach().numpy()
    return arrays


def probe_actions(agent: Any, arrays: dict[str, np.ndarray], count: int = 8) -> dict[str, Any]:
    """OmniSafe's own deterministic actions for ``count`` fixed observations, so that crllk can
    check it plays the same policy from the arrays."""
    actor = agent.agent._actor_critic.actor
    size = arrays["layer0.weight"].shape[1]
    states = torch.as_tensor(np.random.default_rng(0).normal(0.0, 2.0, (count, size)),
                             dtype=torch.float32)
    inputs = states
    if "obs_mean" in arrays:  # what OmniSafe's ObsNormalize feeds the actor
        mean, std, clip = (torch.as_tensor(arrays[k]) for k in ("obs_mean", "obs_std", "obs_clip"))
        inputs = torch.clamp((states - mean) / std, -clip, clip)
    with torch.no_grad():
        actions = actor.predict(inputs, deterministic=True)
    return {"states": states.tolist(), "actions": actions.tolist()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algo", required=True, help="an OmniSafe on-policy algorithm")
    parser.add_argument("--task", required=True, help="a crllk task name")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--frames", type=int, required=True)
    parser.add_argument("--run-dir", required=True, type=Path)
    parser.add_argument("--steps-per-epoch", type=int, default=20_000,
                        help="OmniSafe's default for PPOLag and CPPOPID")
    parser.add_argument("--crllk-python", default=str(ROOT / ".venv" / "bin" / "python"))
    args = parser.parse_args()

    run_dir: Path = args.run_dir.resolve()
    run_dir.mkdir(parents=True, exist_ok=True)
    for stale in ("episodes.csv", "policy.npz", "peer.json", "test.json", "test-mode.json"):
        # a run cut short, or trained again, starts afresh, its old evaluations gone too
        (run_dir / stale).unlink(missing_ok=True)
    probe = TaskServer(args.crllk_python, args.task, run_dir / ".probe.csv")
    description = probe.description
    probe.close()
    (run_dir / ".probe.csv").unlink(missing_ok=True)
    task_environment(args.crllk_python, args.task, run_dir / "episodes.csv", description)

    torch.set_num_threads(1)
    settings = {
        "seed": args.seed,
        "train_cfgs": {"total_steps": args.frames, "torch_threads": 1, "device": "cpu",
                       "vector_env_nums": 1, "parallel": 1},
        "algo_cfgs": {"steps_per_epoch": args.steps_per_epoch},
        "lagrange_cfgs": {"cost_limit": description["cost_limit"]},
        "logger_cfgs": {"log_dir": str(run_dir / "omnisafe"), "use_tensorboard": False,
                        "use_wandb": False, "save_model_freq": 1_000_000},
    }
    started = time.perf_counter()
    agent = omnisafe.Agent(args.algo, f"crllk/{args.task}", custom_cfgs=settings)
    agent.learn()
    wall_s = time.perf_counter() - started
    arrays = policy_arrays(agent)
    with open(run_dir / ".policy.npz.tmp", "wb") as handle:
        np.savez(handle, **arrays)
    os.replace(run_dir / ".policy.npz.tmp", run_dir / "policy.npz")
    frames = (args.frames // args.steps_per_epoch) * args.steps_per_epoch
    document = {"library": "omnisafe", "version": omnisafe.__version__, "algo": args.algo,
                "task": args.task, "seed": args.seed, "frames": frames, "wall_s": wall_s,
                "activation": agent.cfgs.model_cfgs.actor.activation, "settings": settings,
                "probe": probe_actions(agent, arrays), "cost": description}
    (run_dir / ".peer.json.tmp").write_text(json.dumps(document, indent=1) + "\n")
    os.replace(run_dir / ".peer.json.tmp", run_dir / "peer.json")
    print(f"{run_dir}: {frames} frames in {wall_s:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
