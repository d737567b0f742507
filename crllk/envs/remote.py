"""What a remote collector of :class:`crllk.envs.distributed.RayLaneKeepingCollector` runs:
:class:`LaneKeepingCollector`, imported only where collectors are built (TorchRL's collectors
are not needed otherwise)."""

from __future__ import annotations

from typing import Any

import torch
from torchrl.collectors import Collector


class LaneKeepingCollector(Collector):
    """One remote collector: TorchRL's :class:`~torchrl.collectors.Collector` with its policy's
    samples seeded by ``sample_seed`` (torch's generator of the collector's process) and a
    one-line name (Ray prefixes every log line of an actor with its ``repr``)."""

    def __init__(self, *args: Any, sample_seed: int | None = None, **kwargs: Any) -> None:
        if sample_seed is not None:
            torch.manual_seed(sample_seed)
        super().__init__(*args, **kwargs)

    def __repr__(self) -> str:
        return f"LaneKeepingCollector(worker={self.worker_idx})"


__all__ = ["LaneKeepingCollector"]
