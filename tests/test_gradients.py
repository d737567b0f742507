"""Clipping every network's gradient on its own, in one pass: torch's clipping, bit for bit."""

from __future__ import annotations

import itertools

import pytest
import torch

from crllk.rl.gradients import clip_each_group_


def networks(scale: float) -> list[list[torch.nn.Parameter]]:
    """Four small networks with gradients of about ``scale``; one parameter has none."""
    generator = torch.Generator().manual_seed(3)
    groups = []
    for width in (9, 12, 12, 12):
        net = torch.nn.Sequential(torch.nn.Linear(width, 16), torch.nn.Tanh(),
                                  torch.nn.Linear(16, 3))
        for p in net.parameters():
            p.grad = torch.randn(p.shape, generator=generator) * scale
        groups.append(list(net.parameters()))
    groups[2][1].grad = None
    return groups


@pytest.mark.parametrize("scale", [1e-3, 0.3, 10.0])
def test_each_group_is_clipped_as_torch_clips_it(scale):
    ours, theirs = networks(scale), networks(scale)
    clip_each_group_(ours, 0.5)
    for group in theirs:
        torch.nn.utils.clip_grad_norm_(group, 0.5, foreach=True)
    for a, b in zip(itertools.chain(*ours), itertools.chain(*theirs), strict=True):
        assert (a.grad is None and b.grad is None) or torch.equal(a.grad, b.grad)
    norms = [torch.linalg.vector_norm(
                 torch.cat([p.grad.flatten() for p in g if p.grad is not None]))
             for g in ours]
    if scale == 10.0:  # every group was over the bound, and each now sits on it
        assert all(float(n) == pytest.approx(0.5, rel=1e-5) for n in norms)
    if scale == 1e-3:  # under the bound: untouched
        assert all(torch.equal(a.grad, b.grad) for a, b in
                   zip(ours[0], networks(scale)[0], strict=True))


def test_a_group_over_the_bound_is_clipped_and_one_under_it_is_not():
    ours, theirs = networks(1.0), networks(1.0)
    for group in (ours, theirs):
        for p in group[1]:
            p.grad.mul_(1e-4)  # the second network's gradient well under the bound
    clip_each_group_(ours, 0.5)
    for group in theirs:
        torch.nn.utils.clip_grad_norm_(group, 0.5, foreach=True)
    for a, b in zip(itertools.chain(*ours), itertools.chain(*theirs), strict=True):
        assert (a.grad is None and b.grad is None) or torch.equal(a.grad, b.grad)
    untouched = networks(1.0)[1]
    assert all(torch.equal(a.grad, b.grad * 1e-4) for a, b in zip(ours[1], untouched,
                                                                  strict=True))
    first = torch.linalg.vector_norm(torch.cat([p.grad.flatten() for p in ours[0]]))
    assert float(first) == pytest.approx(0.5, rel=1e-5)


def test_groups_without_gradients_are_left_alone():
    groups = networks(1.0)
    for p in groups[0]:
        p.grad = None
    clip_each_group_(groups, 0.5)
    clip_each_group_([groups[0]], 0.5)
    assert all(p.grad is None for p in groups[0])
    assert all(p.grad is not None for p in groups[1])
