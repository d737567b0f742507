"""A TensorDictModule's network run on a tensordict without tensordict's per-call plumbing
(its wrappers cost about as much as a small state network itself)."""

from __future__ import annotations

from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch.distributions import Distribution
from torchrl.modules import ProbabilisticActor


def run_module(module: TensorDictModule, tensordict: TensorDictBase) -> None:
    """Writes into ``tensordict`` what ``module(tensordict)`` writes: the network called on
    the entries of its ``in_keys``, its outputs set under its ``out_keys``. A module whose
    inputs are not a plain list of keys runs as ``module(tensordict)``."""
    if type(module.in_keys) is not list or not hasattr(module, "module"):
        module(tensordict)
        return
    outputs = module.module(*(tensordict.get(key) for key in module.in_keys))
    outputs = outputs if isinstance(outputs, tuple) else (outputs,)
    for key, value in zip(module.out_keys, outputs, strict=True):
        tensordict.set(key, value)


def actor_distribution(actor: ProbabilisticActor, tensordict: TensorDictBase) -> Distribution:
    """``actor.get_dist(tensordict)`` for an actor of one network and its sampler (the
    network's outputs written into ``tensordict``, as there)."""
    modules = actor.module
    if len(modules) != 2 or not isinstance(modules[0], TensorDictModule):
        return actor.get_dist(tensordict)
    run_module(modules[0], tensordict)
    return modules[-1].get_dist(tensordict)


__all__ = ["actor_distribution", "run_module"]
