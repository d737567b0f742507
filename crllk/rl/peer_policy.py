"""A policy a peer library trained (``peers/omnisafe/train.py``), played in crllk's evaluation.

The peer writes its Gaussian actor as arrays only (``policy.npz``, read with
``allow_pickle=False``, so reading it cannot run code): ``layer<k>.weight`` / ``layer<k>.bias`` of
its mean's MLP (``tanh`` between layers, none after the last), ``log_std`` of the action's
standard deviation, and, when it normalised observations, ``obs_mean``, ``obs_std`` and
``obs_clip``: the actor reads ``clip((state - obs_mean) / obs_std, -obs_clip, obs_clip)``.
Its sampled action is Normal(mean, exp(log_std)), its deployed action the mean; the task clips
both to its action box.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import torch
from tensordict.nn import TensorDictModule
from torchrl.modules import ProbabilisticActor

from crllk.errors import ConfigError

ACTIVATIONS = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}
"""Hidden-layer activations a peer's actor may name."""
MAX_LAYERS, MAX_WIDTH = 16, 4096
"""Bounds on a peer actor's size: a file beyond them is refused before building it."""


class PeerMean(torch.nn.Module):
    """Observation normaliser and the MLP of the action's mean, with its log std."""

    def __init__(self, arrays: dict[str, np.ndarray], activation: str):
        super().__init__()
        layers: list[torch.nn.Module] = []
        count = sum(1 for key in arrays if key.endswith(".weight"))
        for k in range(count):
            weight = torch.as_tensor(arrays[f"layer{k}.weight"], dtype=torch.float32)
            linear = torch.nn.Linear(weight.shape[1], weight.shape[0])
            linear.weight.data.copy_(weight)
            linear.bias.data.copy_(torch.as_tensor(arrays[f"layer{k}.bias"]))
            layers.append(linear)
            if k < count - 1:
                layers.append(ACTIVATIONS[activation]())
        self.net = torch.nn.Sequential(*layers)
        self.log_std = torch.nn.Parameter(torch.as_tensor(arrays["log_std"], dtype=torch.float32))
        self.normalised = "obs_mean" in arrays
        for name in ("obs_mean", "obs_std", "obs_clip"):
            value = arrays.get(name, np.zeros(0, np.float32))
            self.register_buffer(name, torch.as_tensor(value, dtype=torch.float32))

    def forward(self, state: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if self.normalised:
            state = torch.maximum(torch.minimum((state - self.obs_mean) / self.obs_std,
                                                self.obs_clip), -self.obs_clip)
        loc = self.net(state)
        return loc, self.log_std.exp().expand_as(loc)


def read_arrays(path: Path, observation_size: int, action_size: int) -> dict[str, np.ndarray]:
    """The arrays of a peer's ``policy.npz``, checked against the task's sizes.

    Raises:
        ConfigError: naming the file and what is wrong with it.
    """
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {key: archive[key] for key in archive.files}
    except (OSError, ValueError, zipfile.BadZipFile) as err:
        raise ConfigError(path, "policy", f"not a peer policy archive ({err})") from None
    count = sum(1 for key in arrays if key.endswith(".weight"))
    if not 1 <= count <= MAX_LAYERS or "log_std" not in arrays:
        raise ConfigError(path, "policy", f"expected 1 to {MAX_LAYERS} layers and log_std")
    width = observation_size
    for k in range(count):
        weight, bias = arrays.get(f"layer{k}.weight"), arrays.get(f"layer{k}.bias")
        if (weight is None or bias is None or weight.ndim != 2 or weight.shape[1] != width
                or bias.shape != (weight.shape[0],) or weight.shape[0] > MAX_WIDTH):
            raise ConfigError(path, f"layer{k}", f"expected a weight [out, {width}] and a "
                              f"bias [out] (out at most {MAX_WIDTH})")
        width = weight.shape[0]
    if width != action_size or arrays["log_std"].shape != (action_size,):
        raise ConfigError(path, "policy", f"expected {action_size} actions")
    for name in ("obs_mean", "obs_std", "obs_clip"):
        if "obs_mean" in arrays and arrays.get(name, np.zeros(0)).shape != (observation_size,):
            raise ConfigError(path, name, f"expected {observation_size} values")
    if not all(np.isfinite(a).all() for a in arrays.values()):
        raise ConfigError(path, "policy", "holds values that are not finite")
    return arrays


def load_peer_policy(path: str | Path, *, observation_size: int, action_size: int,
                     activation: str = "tanh", observation: str = "state") -> ProbabilisticActor:
    """The peer's actor from ``path``: reads ``observation``, writes ``"action"`` (sampled, or
    the mean under deterministic exploration)."""
    if activation not in ACTIVATIONS:
        raise ConfigError(path, "activation", f"expected one of {sorted(ACTIVATIONS)}, got "
                          f"{activation!r}")
    arrays = read_arrays(Path(path), observation_size, action_size)
    module = TensorDictModule(PeerMean(arrays, activation), in_keys=[observation],
                              out_keys=["loc", "scale"])
    return ProbabilisticActor(module, in_keys=["loc", "scale"],
                              distribution_class=torch.distributions.Normal,
                              return_log_prob=False).eval()


__all__ = ["load_peer_policy", "read_arrays"]
