"""A run's deterministic policy as an ONNX file (:class:`~.policy.DeployedPolicy`).

The graph has one input, ``observation`` (uint8 ``[30, 40, 3]`` RGB for pixel runs, ``[30,
40, 3 * history]`` with a frame history, float32 ``[F]`` state features for state runs), and one
output, ``duty`` (float32 ``[2]``: left and right wheel duty cycles in [-1, 1]). What the pilot
needs to feed it is in the model's metadata: ``crllk.observation``, ``crllk.action``,
``crllk.deployed`` (``expected_duty`` or ``expected_action``: how the policy turns its action
distribution into duties), ``crllk.observation_shape``, ``crllk.history`` (images and steps
between them),
``crllk.supersample`` (how much larger training rendered each image before averaging it down),
and where it comes from (``crllk.task``, ``crllk.run``, ``crllk.iteration``, ``crllk.frames``).
"""

from __future__ import annotations

import contextlib
import json
import logging
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import onnx
import torch

from crllk.deployment.onnx_names import INPUT, METADATA_PREFIX, OUTPUT
from crllk.deployment.policy import DeployedPolicy
from crllk.files import atomic_write
from crllk.training.build import build_env
from crllk.training.runs import deployed_form, load_actor, load_run_config

OPSET = 18


def deployed_policy(run_dir: str | Path) -> tuple[DeployedPolicy, dict[str, Any]]:
    """The run's :class:`DeployedPolicy` and its metadata (see the module docstring)."""
    config = load_run_config(run_dir)
    env = build_env(config, num_envs=1, seed=config.eval.seed)
    try:
        actor, info = load_actor(run_dir, env)
        shape = tuple(int(n) for n in env.observation_spec[config.obs.name].shape[1:])
        supersample = env.config.camera.supersample
    finally:
        env.close()
    policy = DeployedPolicy(actor, config.action.name).eval()
    metadata = {"observation": config.obs.name, "action": config.action.name,
                "deployed": deployed_form(config.action.name),
                "observation_shape": json.dumps(list(shape)),
                "history": json.dumps([config.obs.history, config.obs.history_stride]),
                "supersample": str(supersample),
                "task": config.task_name,
                "run": str(Path(run_dir).resolve()), "iteration": str(info["iteration"]),
                "frames": str(info["frames"])}
    return policy, metadata


def example_observation(metadata: dict[str, Any]) -> torch.Tensor:
    """A zero observation of the policy's input shape and type."""
    shape = json.loads(metadata["observation_shape"])
    dtype = torch.uint8 if metadata["observation"] == "pixels" else torch.float32
    return torch.zeros(shape, dtype=dtype)


def export_onnx(policy: DeployedPolicy, metadata: dict[str, Any], out: str | Path) -> Path:
    """Writes ``policy`` to ``out`` as ONNX, with ``metadata`` (atomically)."""
    with torch.no_grad(), _quiet_exporter():
        program = torch.onnx.export(policy, (example_observation(metadata),), dynamo=True,
                                    input_names=[INPUT], output_names=[OUTPUT],
                                    opset_version=OPSET, verbose=False)
    model = program.model_proto
    for key, value in metadata.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = METADATA_PREFIX + key, str(value)
    onnx.checker.check_model(model)
    return atomic_write(out, lambda handle: handle.write(model.SerializeToString()))


@contextlib.contextmanager
def _quiet_exporter() -> Iterator[None]:
    """Silences the exporter's notes on operators this graph does not use (torchvision's) and
    its deprecation warnings; errors still raise."""
    logger = logging.getLogger("torch.onnx")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        logger.setLevel(level)


def export_run(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """Exports the run's policy to ``out`` (default ``<run_dir>/policy.onnx``)."""
    policy, metadata = deployed_policy(run_dir)
    return export_onnx(policy, metadata, Path(run_dir) / "policy.onnx" if out is None else out)
