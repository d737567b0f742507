"""Checkpoint contents that load without running code: tensors and plain containers.

``torch.load(..., weights_only=True)`` builds tensors, ``dict`` (``OrderedDict`` too),
``list``, ``tuple``, ``int``, ``float``, ``str``, ``bool`` and ``None``, and refuses anything
else, because unpickling anything else may call whatever function the file names. A checkpoint
keeps to these types (:func:`first_non_plain` checks); a TensorDict is kept as a dict
(:func:`tensordict_to_plain`, :func:`tensordict_from_plain`).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, ListConfig, OmegaConf
from tensordict import TensorDict, TensorDictBase

PLAIN_SCALARS = (bool, int, float, str, type(None))
"""Values kept as they are (exactly these types: a numpy scalar is a ``float`` subclass, and
unpickling it runs numpy's code)."""
PLAIN_MAPPINGS = (dict, OrderedDict)
PLAIN_SEQUENCES = (list, tuple)
PLAIN_TENSORS = (torch.Tensor, torch.nn.Parameter)


def first_non_plain(value: Any, where: str = "state") -> str | None:
    """Where ``value`` holds something other than tensors and plain containers, as
    ``<where>.<key>: <type>``, or None when it holds nothing else."""
    kind = type(value)
    if kind in PLAIN_SCALARS or kind in PLAIN_TENSORS:
        return None
    if kind in PLAIN_MAPPINGS:
        for key, item in value.items():
            if type(key) not in PLAIN_SCALARS:
                return f"{where}: a key of type {_name(type(key))}"
            found = first_non_plain(item, f"{where}.{key}")
            if found:
                return found
        return None
    if kind in PLAIN_SEQUENCES:
        for index, item in enumerate(value):
            found = first_non_plain(item, f"{where}[{index}]")
            if found:
                return found
        return None
    return f"{where}: {_name(kind)}"


def _name(kind: type) -> str:
    return f"{kind.__module__}.{kind.__qualname__}"


def tensordict_to_plain(td: TensorDictBase) -> dict[str, Any]:
    """``td`` as ``{"entries": ..., "batch_size": [...]}``, a nested tensordict as such a dict
    in ``entries``; not its device (a checkpoint loads onto the CPU).

    Raises:
        TypeError: if an entry is neither a tensor nor a tensordict.
    """
    entries: dict[str, Any] = {}
    for key, value in td.items():
        if isinstance(value, TensorDictBase):
            entries[key] = tensordict_to_plain(value)
        elif type(value) in PLAIN_TENSORS:
            entries[key] = value
        else:
            raise TypeError(f"tensordict entry {key!r} is a {_name(type(value))}, not a tensor")
    return {"entries": entries, "batch_size": list(td.batch_size)}


def tensordict_from_plain(plain: dict[str, Any]) -> TensorDict:
    """The tensordict :func:`tensordict_to_plain` kept: the same entries in the same order and
    batch size."""
    entries = {key: tensordict_from_plain(value) if isinstance(value, dict) else value
               for key, value in plain["entries"].items()}
    return TensorDict(entries, batch_size=plain["batch_size"])


def as_plain(value: Any) -> Any:
    """``value`` with what older checkpoints held in other types in plain ones: numpy arrays
    as tensors, tensordicts as :func:`tensordict_to_plain` keeps them, OmegaConf containers
    as dicts and lists. Containers holding none of these are returned as they are (a module's
    ``state_dict`` keeps its metadata)."""
    if isinstance(value, np.ndarray):
        return torch.from_numpy(value.copy())
    if isinstance(value, TensorDictBase):
        return tensordict_to_plain(value)
    if isinstance(value, DictConfig | ListConfig):
        return OmegaConf.to_container(value, resolve=True)
    if type(value) in PLAIN_MAPPINGS:
        items = {key: as_plain(item) for key, item in value.items()}
        changed = any(items[key] is not item for key, item in value.items())
        return type(value)(items) if changed else value
    if type(value) in PLAIN_SEQUENCES:
        converted = [as_plain(item) for item in value]
        changed = any(new is not old for new, old in zip(converted, value, strict=True))
        return type(value)(converted) if changed else value
    return value


__all__ = ["as_plain", "first_non_plain", "tensordict_from_plain", "tensordict_to_plain"]
