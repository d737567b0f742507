"""Per-simulation action streams (:mod:`crllk.rl.sampling`): the draws follow the policy's
distribution (worked inverse-CDF cases, frequencies, the tanh-Gaussian's value and
log-probability), each simulation's samples come from its own stream whatever the batch, and
the actor writes what TorchRL's sampling writes."""

from __future__ import annotations

import math

import pytest
import torch
from torch.distributions import Categorical
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import TanhNormal

from crllk.config import validate
from crllk.rl.sampling import (
    POLICY_ROWS,
    ActionNoise,
    action_noise_seeds,
    draw,
    draw_categorical,
    sample_actions,
)
from crllk.training.build import build_run
from crllk.training.compose import compose_config


class FixedNoise:
    """Stands in for :class:`ActionNoise` with chosen numbers (one row per simulation)."""

    def __init__(self, rows: torch.Tensor):
        self.rows = rows

    def __len__(self) -> int:
        return len(self.rows)

    def uniform(self, shape=()):
        return self.rows.reshape(len(self.rows), *shape)

    def normal(self, shape=()):
        return self.rows.reshape(len(self.rows), *shape)


def test_categorical_draw_is_the_inverse_cdf():
    """probs (0.2, 0.5, 0.3): F = (0.2, 0.7, 1.0); u in [0, 0.2) gives 0, [0.2, 0.7) gives 1,
    [0.7, 1) gives 2 (a boundary belongs to the action above it)."""
    u = torch.tensor([0.0, 0.1999, 0.2, 0.5, 0.6999, 0.7, 0.9999999])
    probs = torch.tensor([0.2, 0.5, 0.3]).expand(len(u), 3)
    action, log_prob = draw(Categorical(probs=probs), FixedNoise(u))
    assert action.tolist() == [0, 0, 1, 1, 1, 2, 2]
    expected = torch.tensor([0.2, 0.2, 0.5, 0.5, 0.5, 0.3, 0.3]).log()
    torch.testing.assert_close(log_prob, expected)


def test_categorical_draws_have_the_policy_frequencies():
    """20,000 draws from one stream per row: each action's frequency within 4 standard errors
    of its probability (about 0.012 here)."""
    probs = torch.tensor([0.1, 0.6, 0.3])
    noise = ActionNoise.seeded(7, 20_000)
    action, _ = draw(Categorical(probs=probs.expand(20_000, 3)), noise)
    frequencies = torch.bincount(action, minlength=3).double() / 20_000
    bound = 4 * torch.sqrt(probs.double() * (1 - probs.double()) / 20_000)
    assert ((frequencies - probs.double()).abs() < bound).all(), frequencies


def test_tanh_normal_draw_is_the_reparameterised_sample_and_its_log_probability():
    """ε = (0.5, -1): preimage loc + scale·ε = (0.1 + 0.2·0.5, -0.3 + 0.4·(-1)) = (0.2, -0.7),
    action tanh of it; log p = Σ log N(preimage) − Σ log(1 − tanh²), which is also what the
    distribution gives for the action."""
    loc, scale = torch.tensor([[0.1, -0.3]]), torch.tensor([[0.2, 0.4]])
    distribution = TanhNormal(loc, scale, low=-1.0, high=1.0)
    action, log_prob = draw(distribution, FixedNoise(torch.tensor([[0.5, -1.0]])))
    preimage = torch.tensor([0.2, -0.7], dtype=torch.float64)
    torch.testing.assert_close(action[0], preimage.tanh().float())
    normal = (-0.5 * torch.tensor([0.5, -1.0], dtype=torch.float64) ** 2
              - torch.log(torch.tensor([0.2, 0.4], dtype=torch.float64))
              - 0.5 * math.log(2 * math.pi))
    expected = (normal - torch.log1p(-preimage.tanh() ** 2)).sum()
    torch.testing.assert_close(log_prob[0].double(), expected, rtol=1e-6, atol=1e-6)
    torch.testing.assert_close(log_prob, distribution.log_prob(action), rtol=1e-5, atol=1e-5)


def test_streams_do_not_depend_on_the_batch():
    """Four streams drawn together equal the same four continued as two slices of two."""
    together = ActionNoise.seeded(3, 4)
    states = together.states()
    first, second = ActionNoise.from_states(states[:2]), ActionNoise.from_states(states[2:])
    for _ in range(3):
        joint = together.uniform((2,))
        assert torch.equal(joint, torch.cat([first.uniform((2,)), second.uniform((2,))]))
    assert all(torch.equal(a, b) for a, b in
               zip(together.states(), first.states() + second.states(), strict=True))


def test_stream_seeds_differ_by_seed_and_simulation():
    seeds = action_noise_seeds(0, 16) + action_noise_seeds(1, 16)
    assert len(set(seeds)) == 32
    assert action_noise_seeds(0, 4) == action_noise_seeds(0, 16)[:4]
    assert all(0 <= s < 2**63 for s in seeds)


def test_load_states_refuses_a_different_count():
    with pytest.raises(ValueError, match="3 stream states for 2 simulations"):
        ActionNoise.seeded(0, 2).load_states(ActionNoise.seeded(0, 3).states())


@pytest.mark.parametrize("action", ["discrete", "continuous"])
def test_sample_actions_writes_what_the_actor_writes_and_each_row_alone_acts_the_same(action):
    """The same keys, shapes and dtypes as the actor's own sampling; and a simulation's action
    is the same whether its row is drawn with the 2 others (padded to POLICY_ROWS) or alone."""
    config = validate(compose_config(["task=small_loop", "obs=pixels", "workers=1",
                                      "num_envs=3", f"action={action}"]))
    env, learner, _, _ = build_run(config)
    try:
        td = env.reset()
        with set_exploration_type(ExplorationType.RANDOM), torch.no_grad():
            reference = learner.actor(td.clone())
            ours = sample_actions(learner.actor, td.clone(), ActionNoise.seeded(0, 3))
            alone = [sample_actions(learner.actor, td[i:i + 1].clone(),
                                    ActionNoise.from_states([ActionNoise.seeded(0, 3)
                                                             .states()[i]]))
                     for i in range(3)]
    finally:
        env.close()
    assert set(ours.keys(True, True)) == set(reference.keys(True, True))
    for key in reference.keys(True, True):
        assert ours[key].shape == reference[key].shape and ours[key].dtype == reference[key].dtype
    for i, row in enumerate(alone):
        for key in ("action", "action_log_prob"):
            assert torch.equal(row[key][0], ours[key][i]), (key, i)
    assert POLICY_ROWS == 8


def test_sample_actions_refuses_a_batch_without_its_streams():
    config = validate(compose_config(["task=small_loop", "obs=state", "num_envs=2"]))
    env, learner, _, _ = build_run(config)
    try:
        with pytest.raises(ValueError, match="3 action streams for a batch of \\(2,\\)"):
            sample_actions(learner.actor, env.reset(), ActionNoise.seeded(0, 3))
    finally:
        env.close()


@pytest.mark.parametrize("scale", [0.01, 1.0, 30.0])
def test_drawing_from_logits_is_the_categorical_draw_bit_for_bit(scale):
    """The collection's shortcut (no distribution object) draws the same actions with the
    same log-probabilities as ``Categorical(logits=...)``, for flat, ordinary and extreme
    logits, from the same streams."""
    logits = torch.randn(64, 3, generator=torch.Generator().manual_seed(5)) * scale
    logits[0] = torch.tensor([80.0, -80.0, 0.0])  # a probability that rounds to 0
    ours, theirs = ActionNoise.seeded(11, 64), ActionNoise.seeded(11, 64)
    for _ in range(5):
        action, log_prob = draw_categorical(logits, ours)
        expected_action, expected_log_prob = draw(Categorical(logits=logits), theirs)
        assert torch.equal(action, expected_action)
        assert torch.equal(log_prob, expected_log_prob)
    assert action.dtype == torch.int64 and log_prob.shape == (64,)


def test_a_categorical_policy_draws_through_the_shortcut_and_a_probs_one_does_not(monkeypatch):
    """The project's discrete actor (logits) never builds its distribution while collecting;
    a sampler fed probabilities under the key ``logits`` is not mistaken for it."""
    from tensordict import TensorDict
    from tensordict.nn import TensorDictModule
    from torchrl.modules import ProbabilisticActor

    import crllk.rl.sampling as sampling

    config = validate(compose_config(["task=small_loop", "obs=state", "num_envs=2",
                                      "workers=1"]))
    env, learner, _, _ = build_run(config)
    td = env.reset()
    env.close()

    def refuse(*args):
        raise AssertionError("built the distribution")

    monkeypatch.setattr(sampling, "draw", refuse)
    with torch.no_grad():
        sample_actions(learner.actor, td, ActionNoise.seeded(0, 2))
    probabilities = ProbabilisticActor(
        TensorDictModule(lambda x: torch.softmax(x, -1), in_keys=["x"], out_keys=["logits"]),
        in_keys={"probs": "logits"}, distribution_class=Categorical, return_log_prob=True)
    with pytest.raises(AssertionError, match="built the distribution"):
        sample_actions(probabilities, TensorDict({"x": torch.zeros(2, 3)}, batch_size=[2]),
                       ActionNoise.seeded(0, 2))
