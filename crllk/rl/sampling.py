"""The behaviour policy's action samples in training, one random stream per simulation.

:class:`ActionNoise` holds one ``torch.Generator`` per simulation; :func:`sample_actions`
draws each simulation's action from its own stream (a uniform number for a categorical policy,
standard normals for a tanh-Gaussian one) and maps it through the distribution the policy
computed. A simulation's samples therefore depend only on its stream and its observations,
never on which process steps it or how many others share the batch: the simulations can be
collected in one process or split among several (:mod:`crllk.rl.collection`) and the batch is
the same.

The samples follow the policy's distribution exactly: inverse-CDF sampling for
``Categorical`` (action ``k`` when ``F(k-1) <= u < F(k)``), the reparameterisation
``loc + scale * ε`` through the tanh transform for ``TanhNormal``, with the log-probability of
the same draw that TorchRL's ``ProbabilisticActor`` writes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase
from torch.distributions import Categorical, Distribution, Normal
from torch.distributions.utils import _sum_rightmost
from torchrl.modules import ProbabilisticActor, TanhNormal

from crllk.rl.direct import is_plain

ACTION_NOISE_TAG = 0xAC7
"""Mixed into the run's seed for the action streams, so they never equal the spawn streams
(:func:`crllk.envs.batched.sub_env_seeds`) of the same seed."""


def action_noise_seeds(seed: int, count: int) -> list[int]:
    """The seed of each simulation's action stream: a 63-bit word from each of ``count``
    children of ``np.random.SeedSequence([seed, ACTION_NOISE_TAG])``."""
    children = np.random.SeedSequence([seed, ACTION_NOISE_TAG]).spawn(count)
    return [int(child.generate_state(1, np.uint64)[0] >> np.uint64(1)) for child in children]


class ActionNoise:
    """One random stream per simulation for the behaviour policy's samples."""

    def __init__(self, generators: Sequence[torch.Generator]):
        self.generators = list(generators)

    @classmethod
    def seeded(cls, seed: int, count: int) -> ActionNoise:
        """``count`` streams seeded from the run's ``seed`` (:func:`action_noise_seeds`)."""
        return cls([torch.Generator().manual_seed(s) for s in action_noise_seeds(seed, count)])

    @classmethod
    def from_states(cls, states: Sequence[torch.Tensor]) -> ActionNoise:
        """Streams continuing from :meth:`states` (of this object or of a slice of it)."""
        noise = cls([torch.Generator() for _ in states])
        noise.load_states(states)
        return noise

    def __len__(self) -> int:
        return len(self.generators)

    def states(self) -> list[torch.Tensor]:
        """Each stream's state (a uint8 tensor), in simulation order."""
        return [generator.get_state() for generator in self.generators]

    def load_states(self, states: Sequence[torch.Tensor]) -> None:
        """Continue every stream from ``states`` (as :meth:`states` returned them).

        Raises:
            ValueError: if there are not as many states as streams.
        """
        if len(states) != len(self.generators):
            raise ValueError(f"{len(states)} stream states for {len(self.generators)} "
                             "simulations")
        for generator, state in zip(self.generators, states, strict=True):
            generator.set_state(state)

    def uniform(self, shape: Sequence[int] = ()) -> torch.Tensor:
        """``[N, *shape]`` uniform numbers in [0, 1), row ``i`` from stream ``i``."""
        return torch.stack([torch.rand(tuple(shape), generator=g) for g in self.generators])

    def normal(self, shape: Sequence[int] = ()) -> torch.Tensor:
        """``[N, *shape]`` standard normal numbers, row ``i`` from stream ``i``."""
        return torch.stack([torch.randn(tuple(shape), generator=g) for g in self.generators])


def draw(distribution: Distribution, noise: ActionNoise) -> tuple[torch.Tensor, torch.Tensor]:
    """One sample of ``distribution`` (batch ``[N]``) per simulation, from its own stream,
    and the sample's log-probability.

    Raises:
        TypeError: for a distribution other than ``Categorical`` and ``TanhNormal``.
    """
    if isinstance(distribution, Categorical):
        action = _inverse_cdf(distribution.probs, noise)
        return action, distribution.log_prob(action)
    if isinstance(distribution, TanhNormal):
        # In double precision, rounded once at the end: the vectorised float32 kernels round
        # differently with the batch's size, and the sample must not depend on it.
        base = distribution.base_dist
        epsilon = noise.normal(distribution.event_shape).to(torch.float64)
        preimage = base.mean.double() + epsilon * base.stddev.double()
        transform = distribution.transforms[0]
        action = transform(preimage)
        log_prob = Normal(base.mean.double(), base.stddev.double()).log_prob(preimage)
        log_prob = log_prob - transform.log_abs_det_jacobian(preimage, action)
        dtype = base.mean.dtype
        return action.to(dtype), _sum_rightmost(log_prob, len(distribution.event_shape)).to(dtype)
    raise TypeError(f"no per-simulation sampling for {type(distribution).__name__}")


def draw_categorical(logits: torch.Tensor, noise: ActionNoise
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`draw` of ``Categorical(logits=logits)``, bit for bit, without building the
    distribution (whose checks cost more than the policy's small network during collection):
    the same normalised logits, probabilities and draw."""
    normalized = logits - logits.logsumexp(dim=-1, keepdim=True)
    action = _inverse_cdf(torch.softmax(normalized, dim=-1), noise)
    return action, normalized.gather(-1, action.unsqueeze(-1)).squeeze(-1)


def _inverse_cdf(probs: torch.Tensor, noise: ActionNoise) -> torch.Tensor:
    """Action ``k`` of each row where ``F(k-1) <= u < F(k)``, ``u`` from the row's stream."""
    u = noise.uniform().to(probs.dtype)
    action = torch.searchsorted(probs.cumsum(-1), u.unsqueeze(-1), right=True).squeeze(-1)
    return action.clamp_max(probs.shape[-1] - 1)  # u above a rounded-down total


POLICY_ROWS = 8
"""The policy's batch during collection is padded to a multiple of this many rows: CPU kernels
choose their code path by batch size (a batch of 1 or 2 rounds differently from one of 8). On
an AMD EPYC a row's outputs then do not depend on the others, so a simulation acts the same
whether its process steps 1, 8 or 16 of them; on an Intel Xeon they may still differ in the
last bit."""


def sample_actions(actor: ProbabilisticActor, tensordict: TensorDictBase,
                   noise: ActionNoise) -> TensorDictBase:
    """What ``actor(tensordict)`` writes when it samples (the distribution's parameters, the
    action and its log-probability), with simulation ``i``'s action drawn from stream ``i``
    and the network run on a batch padded to :data:`POLICY_ROWS`.

    Raises:
        ValueError: if the batch and the streams differ in size.
    """
    count = len(noise)
    if tensordict.batch_size != torch.Size([count]):
        raise ValueError(f"{count} action streams for a batch of {tuple(tensordict.batch_size)}")
    network, sampler = actor.module[0], actor.module[-1]  # parameters, then the sample
    if not is_plain(network):  # tensordict's own call, unpadded
        network(tensordict)
        return _draw_into(tensordict, sampler, noise)
    inputs = [tensordict.get(key) for key in network.in_keys]
    padded_count = -(-count // POLICY_ROWS) * POLICY_ROWS
    if padded_count != count:
        rows = torch.arange(padded_count).clamp_max(count - 1)  # the last row repeated
        inputs = [value[rows] for value in inputs]
    outputs = network.module(*inputs)  # the bare network: no tensordict plumbing per step
    outputs = outputs if isinstance(outputs, tuple) else (outputs,)
    for key, value in zip(network.out_keys, outputs, strict=True):
        tensordict.set(key, value[:count])
    return _draw_into(tensordict, sampler, noise)


def _draw_into(tensordict: TensorDictBase, sampler: Any, noise: ActionNoise) -> TensorDictBase:
    """The action and its log-probability drawn from the distribution whose parameters are in
    ``tensordict``, written into it under the sampler's keys."""
    if (sampler.distribution_class is Categorical and list(sampler.dist_keys) == ["logits"]
            and not sampler.distribution_kwargs):  # the distribution takes the logits as is
        action, log_prob = draw_categorical(tensordict.get(sampler.in_keys[0]), noise)
    else:
        action, log_prob = draw(sampler.get_dist(tensordict), noise)
    tensordict.set(sampler.out_keys[0], action)
    tensordict.set(sampler.log_prob_key, log_prob)
    return tensordict


__all__ = ["POLICY_ROWS", "ActionNoise", "action_noise_seeds", "draw", "draw_categorical",
           "sample_actions"]
