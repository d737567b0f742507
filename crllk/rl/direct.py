"""A TensorDictModule's network run on a tensordict without tensordict's per-call plumbing
(its wrappers cost about as much as a small state network itself)."""

from __future__ import annotations

from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch.distributions import Distribution
from torchrl.modules import ProbabilisticActor, ValueOperator


def is_plain(module: object) -> bool:
    """Whether ``module(tensordict)`` only calls its network on the entries of its
    ``in_keys``, in order, and sets its outputs under its ``out_keys`` in place (a plain
    :class:`TensorDictModule` or :class:`ValueOperator`: no keyword inputs, method, reading
    options, hooks, selected outputs or copy)."""
    return (type(module) in (TensorDictModule, ValueOperator)
            and getattr(module, "_kwargs", None) is None
            and getattr(module, "method", None) is None
            and not getattr(module, "method_kwargs", None)
            and not getattr(module, "_get_kwargs", None)
            and getattr(module, "inplace", True) is True
            and not module._forward_hooks and not module._forward_pre_hooks
            and list(module.out_keys) == list(getattr(module, "out_keys_source",
                                                      module.out_keys))
            and "_" not in module.out_keys)


def run_module(module: TensorDictModule, tensordict: TensorDictBase) -> None:
    """Writes into ``tensordict`` what ``module(tensordict)`` writes: for a plain module
    (:func:`is_plain`) the network called on the entries of its ``in_keys``, its outputs set
    under its ``out_keys``; any other module runs as ``module(tensordict)``."""
    if not is_plain(module):
        module(tensordict)
        return
    outputs = module.module(*(tensordict.get(key) for key in module.in_keys))
    outputs = outputs if isinstance(outputs, tuple) else (outputs,)
    for key, value in zip(module.out_keys, outputs, strict=True):
        tensordict.set(key, value)


def actor_distribution(actor: ProbabilisticActor, tensordict: TensorDictBase) -> Distribution:
    """``actor.get_dist(tensordict)`` (the network's outputs written into ``tensordict``, as
    there), with a plain network (:func:`is_plain`) run directly; an actor of more than a
    network and its sampler runs as ``actor.get_dist``."""
    modules = actor.module
    if len(modules) != 2 or not is_plain(modules[0]):
        return actor.get_dist(tensordict)
    run_module(modules[0], tensordict)
    return modules[-1].get_dist(tensordict)


__all__ = ["actor_distribution", "is_plain", "run_module"]
