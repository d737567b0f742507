"""Gradient clipping of several networks, each on its own, in one pass."""

from __future__ import annotations

from collections.abc import Sequence

import torch


@torch.no_grad()
def clip_each_group_(groups: Sequence[Sequence[torch.nn.Parameter]], max_norm: float) -> None:
    """Scales each group's gradients to a total 2-norm of at most ``max_norm``, bit for bit as
    ``torch.nn.utils.clip_grad_norm_(group, max_norm, foreach=True)`` on every group in turn
    does, with one norm kernel and one multiply for all of them (parameters without a
    gradient are left out, as there). The groups must be disjoint (each network's own
    parameters), on one device and of one dtype, as the learner's are."""
    grads = [[p.grad for p in group if p.grad is not None] for group in groups]
    flat = [grad for group in grads for grad in group]
    if not flat:
        return
    norms = torch._foreach_norm(flat, 2.0)
    coefficients: list[torch.Tensor] = []
    for group in grads:
        if group:
            first = len(coefficients)
            total = torch.linalg.vector_norm(torch.stack(norms[first:first + len(group)]), 2.0)
            coefficients.extend([torch.clamp(max_norm / (total + 1e-6), max=1.0)] * len(group))
    torch._foreach_mul_(flat, coefficients)


__all__ = ["clip_each_group_"]
