"""Numeric and key-remap tests of the PPO loss with its critics, its GAE helper, and the loss fed
by the λ-combination (:mod:`crllk.rl.lagrangian_advantage`)."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torch.distributions import Categorical
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import ClipPPOLoss

from crllk.rl.lagrangian_advantage import LagrangianAdvantage
from crllk.rl.loss import CriticsPPOLoss, make_advantage_modules

_OBS_DIM = 4
_N_ACTIONS = 3
_BATCH = 32
_HIDDEN = 16
_COSTS = ("lane", "collision")
_LOSS_KEYS = ("loss_objective", "loss_critic", "loss_cost_critic", "loss_entropy")


@contextlib.contextmanager
def _seeded(seed: int) -> Iterator[None]:
    """Seeds torch inside the block only; the global generator is restored afterwards."""
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        yield


def _mlp(out_features: int) -> nn.Module:
    return MLP(in_features=_OBS_DIM, out_features=out_features, num_cells=[_HIDDEN])


def _critic(out_key: str) -> ValueOperator:
    return ValueOperator(_mlp(1), in_keys=["observation"], out_keys=[out_key])


def _categorical_actor() -> ProbabilisticActor:
    logits = TensorDictModule(_mlp(_N_ACTIONS), in_keys=["observation"], out_keys=["logits"])
    return ProbabilisticActor(
        logits, in_keys=["logits"], distribution_class=Categorical, return_log_prob=True
    )


def _tanh_normal_actor(action_dim: int) -> ProbabilisticActor:
    params = TensorDictModule(
        nn.Sequential(_mlp(2 * action_dim), NormalParamExtractor()),
        in_keys=["observation"],
        out_keys=["loc", "scale"],
    )
    return ProbabilisticActor(
        params, in_keys=["loc", "scale"], distribution_class=TanhNormal, return_log_prob=True
    )


def _networks(actor_factory=_categorical_actor, seed: int = 0):
    """(actor, reward critic, {cost: critic}), initialised under a fixed seed."""
    with _seeded(seed):
        actor = actor_factory()
        critic = _critic("state_value")
        cost_critics = {name: _critic(f"state_value_{name}") for name in _COSTS}
    return actor, critic, cost_critics


def _batch(actor: ProbabilisticActor, actions: torch.Tensor, g: torch.Generator) -> TensorDict:
    """A batch of 32 transitions: the actor's log-probs perturbed so that some ratios clip,
    random advantages and value targets for the reward and both costs (the reward's advantage
    in ``advantage_reward``, before the λ-combination)."""
    td = TensorDict({"observation": torch.randn(_BATCH, _OBS_DIM, generator=g)}, [_BATCH])
    td["action"] = actions
    with torch.no_grad():
        log_prob = actor.get_dist(td).log_prob(actions)
    td["action_log_prob"] = log_prob + 0.3 * torch.randn(_BATCH, generator=g)
    for suffix in ("", *(f"_{name}" for name in _COSTS)):
        td[f"advantage{suffix or '_reward'}"] = torch.randn(_BATCH, 1, generator=g)
        td[f"value_target{suffix}"] = torch.randn(_BATCH, 1, generator=g)
    return td


def _categorical_batch(actor: ProbabilisticActor, seed: int = 1) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    return _batch(actor, torch.randint(0, _N_ACTIONS, (_BATCH,), generator=g), g)


def _loss(lagrange=(0.0, 0.0), **kwargs) -> tuple[CriticsPPOLoss, TensorDict]:
    """The loss and a batch whose advantage the λ-combination wrote with ``lagrange``."""
    actor, critic, cost_critics = _networks()
    loss = CriticsPPOLoss(actor, critic, cost_critics, **kwargs)
    return loss, LagrangianAdvantage(_COSTS, lagrange=lagrange)(_categorical_batch(actor))


# ---------------------------------------------------------------------- (a) λ = 0 is PPO


@pytest.mark.parametrize("normalize", [False, True])
def test_zero_multipliers_match_torchrl_clip_ppo(normalize):
    loss, td = _loss(normalize_advantage=normalize)
    reference = ClipPPOLoss(
        loss.actor_network,
        loss.critic_network,
        clip_epsilon=0.2,
        entropy_coeff=0.01,
        critic_coeff=1.0,
        loss_critic_type="l2",  # (V − G)², as ours
        normalize_advantage=normalize,
    )
    ours, theirs = loss(td), reference(td)
    assert 0.0 < theirs["clip_fraction"] < 1.0  # the clip is exercised on this batch
    for key in ("loss_objective", "loss_entropy", "entropy", "clip_fraction", "loss_critic"):
        torch.testing.assert_close(ours[key], theirs[key], msg=key)


def test_input_batch_is_not_modified():
    loss, td = _loss()
    keys_before = set(td.keys(include_nested=True))
    loss(td)
    assert set(td.keys(include_nested=True)) == keys_before


# ------------------------------------------------------- (b) λ lowers the objective as computed


def _unit_ratio_batch(loss: CriticsPPOLoss) -> TensorDict:
    """A_r = 1 everywhere; A_lane = 3 on the first half, 0 on the second; A_collision = 0.5.
    The stored log-probs are the current ones, so every ratio ρ is exactly 1."""
    td = _categorical_batch(loss.actor_network)
    with torch.no_grad():
        td["action_log_prob"] = loss.actor_network.get_dist(td).log_prob(td["action"])
    half = _BATCH // 2
    td["advantage_reward"] = torch.ones(_BATCH, 1)
    td["advantage_lane"] = torch.cat([torch.full((half, 1), 3.0), torch.zeros(half, 1)])
    td["advantage_collision"] = torch.full((_BATCH, 1), 0.5)
    return td


@pytest.mark.parametrize(
    ("lagrange", "high_cost", "no_cost"),
    [
        # A = (A_r − λ_lane·A_lane − λ_coll·A_coll) / (1 + λ_lane + λ_coll)
        ((0.0, 0.0), 1.0, 1.0),  # (1 − 0 − 0) / 1
        ((2.0, 0.0), -5.0 / 3.0, 1.0 / 3.0),  # (1 − 6) / 3 and (1 − 0) / 3
        ((2.0, 1.0), -1.375, 0.125),  # (1 − 6 − 0.5) / 4 and (1 − 0 − 0.5) / 4
    ],
)
def test_combined_advantage_follows_the_formula(lagrange, high_cost, no_cost):
    loss, _ = _loss()
    td = LagrangianAdvantage(_COSTS, lagrange=lagrange)(_unit_ratio_batch(loss))
    half = _BATCH // 2
    expected = torch.tensor([[high_cost]] * half + [[no_cost]] * half)
    torch.testing.assert_close(td["advantage"], expected)
    # With ρ = 1 no sample is clipped and the surrogate is mean(ρ·A) = mean(A):
    out = loss(td)
    assert out["clip_fraction"] == 0.0
    torch.testing.assert_close(out["loss_objective"], -expected.mean())


def test_a_larger_lane_multiplier_lowers_the_objective():
    # λ = 0: loss_objective = −mean(A_r) = −1
    # λ_lane = 2: loss_objective = −mean(−5/3 on 16 samples, 1/3 on 16) = −(−4/3)/2 = 2/3
    # i.e. the surrogate objective falls from 1 to −2/3, driven by the high-lane-cost samples,
    # whose advantage turns from +1 to −5/3 (their actions become less likely).
    loss, _ = _loss()
    td = _unit_ratio_batch(loss)
    combination = LagrangianAdvantage(_COSTS)
    objectives = []
    for lane in (0.0, 0.5, 2.0, 10.0):
        combination.set_multipliers({"lane": lane, "collision": 0.0})
        objectives.append(loss(combination(td))["loss_objective"].item())
    assert objectives[0] == pytest.approx(-1.0)
    assert objectives[2] == pytest.approx(2.0 / 3.0)
    assert objectives == sorted(objectives)  # the loss rises (objective falls) with λ_lane


# ---------------------------------------------------------------------------- (c) gradients


def _has_gradient(module: nn.Module) -> bool:
    return any(p.grad is not None and p.grad.abs().sum() > 0 for p in module.parameters())


def test_gradients_reach_every_network():
    loss, td = _loss(lagrange=(1.0, 0.5))
    out = loss(td)
    sum(out[key] for key in _LOSS_KEYS).backward()
    assert _has_gradient(loss.actor_network)
    assert _has_gradient(loss.critic_network)
    for name in _COSTS:
        assert _has_gradient(loss.cost_critics[name]), name


def test_objective_reaches_only_the_actor():
    loss, td = _loss(lagrange=(1.0, 0.5))
    loss(td)["loss_objective"].backward()
    assert _has_gradient(loss.actor_network)
    assert not _has_gradient(loss.critic_network)
    assert not any(_has_gradient(critic) for critic in loss.cost_critics.values())


def test_diagnostics_are_detached_and_named():
    loss, td = _loss(lagrange=(1.0, 0.5))
    out = loss(td)
    assert set(out.keys()) == set(loss.out_keys)
    for key in ("entropy", "kl_approx", "clip_fraction", "explained_variance",
                "explained_variance_lane", "explained_variance_collision"):
        assert not out[key].requires_grad, key
    assert out["kl_approx"] >= 0.0  # (ρ − 1) − log ρ >= 0


# ------------------------------------------------------------------------- (d) key remapping


def test_set_keys_remaps_what_the_loss_reads():
    loss, td = _loss(lagrange=(2.0, 1.0))
    expected = loss(td)
    renamed = td.clone()
    renamed["adv"] = renamed.pop("advantage")
    renamed["costs", "lane", "target"] = renamed.pop("value_target_lane")
    loss.set_keys(advantage="adv", value_target_lane=("costs", "lane", "target"))
    assert loss.cost_keys("lane")[0] == ("costs", "lane", "target")
    out = loss(renamed)
    for key in _LOSS_KEYS:
        torch.testing.assert_close(out[key], expected[key], msg=key)
    with pytest.raises(KeyError, match="'adv'"):
        loss(td)  # the old names are no longer read


def test_unknown_key_names_and_shared_value_keys_raise():
    loss, _ = _loss()
    with pytest.raises(ValueError, match="not an accepted tensordict key"):
        loss.set_keys(advantage_speed="advantage_speed")
    actor, critic, _ = _networks()
    with pytest.raises(ValueError, match="its own value key"):
        CriticsPPOLoss(actor, critic, {"lane": _critic("state_value")})


# ---------------------------------------------------------------------- (e) the GAE helper


def _fixed_linear_critic(out_key: str, slope: float) -> ValueOperator:
    """V(s) = slope · s for a one-dimensional observation s."""
    linear = nn.Linear(1, 1)
    with torch.no_grad():
        linear.weight.fill_(slope)
        linear.bias.zero_()
    return ValueOperator(linear, in_keys=["observation"], out_keys=[out_key])


def _toy_trajectory() -> TensorDict:
    """Five steps, s = 1.0, 0.8, ..., 0.2 → s' = 0.8, ..., 0.0, terminated at the last step."""
    obs = torch.tensor([[1.0], [0.8], [0.6], [0.4], [0.2]])
    end = torch.tensor([[False]] * 4 + [[True]])
    return TensorDict(
        {
            "observation": obs,
            "next": {
                "observation": obs - 0.2,
                "reward": torch.ones(5, 1),
                "cost_lane": torch.tensor([[0.5], [1.0], [0.0], [2.0], [1.0]]),
                "cost_collision": torch.zeros(5, 1),
                "done": end,
                "terminated": end,
            },
        },
        [5],
    )


def test_gae_helper_matches_a_manual_computation():
    critic = _fixed_linear_critic("state_value", slope=2.0)
    cost_critics = {
        "lane": _fixed_linear_critic("state_value_lane", slope=1.0),
        "collision": _fixed_linear_critic("state_value_collision", slope=0.0),
    }
    modules = make_advantage_modules(0.95, 0.95, critic, cost_critics)
    td = modules(_toy_trajectory())
    # Lane: V(s) = s, γ = λ = 0.95, γλ = 0.9025, δ_t = c_t + γ(1 − term_t)V(s'_t) − V(s_t)
    #   δ_4 = 1.0 + 0 − 0.2          = 0.80   (terminated: no bootstrap)
    #   δ_3 = 2.0 + 0.95·0.2 − 0.4   = 1.79
    #   δ_2 = 0.0 + 0.95·0.4 − 0.6   = −0.22
    #   δ_1 = 1.0 + 0.95·0.6 − 0.8   = 0.77
    #   δ_0 = 0.5 + 0.95·0.8 − 1.0   = 0.26
    # A_t = δ_t + 0.9025·A_{t+1}:
    #   A_4 = 0.8
    #   A_3 = 1.79 + 0.9025·0.8      = 2.512
    #   A_2 = −0.22 + 0.9025·2.512   = 2.04708
    #   A_1 = 0.77 + 0.9025·2.04708  = 2.6174897
    #   A_0 = 0.26 + 0.9025·2.6174897 = 2.622284454...
    lane = torch.tensor([[2.6222844], [2.6174897], [2.04708], [2.512], [0.8]])
    torch.testing.assert_close(td["advantage_lane"], lane)
    # G_t = A_t + V(s_t)
    torch.testing.assert_close(td["value_target_lane"], lane + td["observation"])
    # Collision: zero costs and V = 0, so zero advantage.
    torch.testing.assert_close(td["advantage_collision"], torch.zeros(5, 1))
    # Reward: V(s) = 2s, r = 1: δ_4 = 1 − 0.4 = 0.6, δ_3 = 1 + 0.95·0.4 − 0.8 = 0.58
    #   A_4 = 0.6, A_3 = 0.58 + 0.9025·0.6 = 1.1215
    torch.testing.assert_close(td["advantage_reward"][3:], torch.tensor([[1.1215], [0.6]]))


def test_costs_discounted_by_their_own_gamma():
    """cost_gamma = 0.99 discounts the costs and leaves the reward at γ = 0.95. Lane: V(s) = s,
    λ = 1, so A_t = Σ_k γ_c^k c_{t+k} − V(s_t) (terminated at the last step):
      A_3 = 2.0 + 0.99·1.0 − 0.4 = 2.59,   A_4 = 1.0 − 0.2 = 0.8;
    reward: V(s) = 2s, r = 1: A_3 = 1 + 0.95·1 − 0.8 = 1.15, as at γ = 0.95 alone."""
    critic = _fixed_linear_critic("state_value", slope=2.0)
    cost_critics = {
        "lane": _fixed_linear_critic("state_value_lane", slope=1.0),
        "collision": _fixed_linear_critic("state_value_collision", slope=0.0),
    }
    td = make_advantage_modules(0.95, 1.0, critic, cost_critics, cost_gamma=0.99)(
        _toy_trajectory())
    torch.testing.assert_close(td["advantage_lane"][3:], torch.tensor([[2.59], [0.8]]))
    torch.testing.assert_close(td["advantage_reward"][3:], torch.tensor([[1.15], [0.6]]))
    # A_0 = 0.5 + 0.99·1.0 + 0.99²·0.0 + 0.99³·2.0 + 0.99⁴·1.0 − 1.0
    first = 0.5 + 0.99 + 0.99**3 * 2.0 + 0.99**4 - 1.0
    torch.testing.assert_close(td["advantage_lane"][0], torch.tensor([first]))
    with pytest.raises(ValueError, match="cost_gamma"):
        make_advantage_modules(0.95, 1.0, critic, cost_critics, cost_gamma=1.5)


@pytest.mark.parametrize(("overrides", "tail"), [([], 10.0 * 0.95 / 0.05),
                                                  (["ppo.cost_gamma=0.99"], 10.0 * 0.99 / 0.01)])
def test_off_road_tail_is_discounted_as_the_costs_are(overrides, tail):
    """With absorbing_off_road, a terminated step's lane cost gains the discounted sum of
    off_road_lane_cost (10 dm) for ever after, at the costs' discount."""
    from crllk.config import validate
    from crllk.tasks.config import load_task_config
    from crllk.training.compose import compose_config
    from crllk.training.updates import shape_signals

    config = validate(compose_config(["task=small_loop", "absorbing_off_road=true", *overrides]))
    td = _toy_trajectory()
    lane_before = td["next", "cost_lane"].clone()
    shape_signals(td, config, load_task_config("small_loop"))
    added = td["next", "cost_lane"] - lane_before
    torch.testing.assert_close(added, torch.tensor([[0.0]] * 4 + [[tail]]))


def test_the_learner_discounts_costs_by_cost_gamma():
    """``ppo.cost_gamma`` reaches the PPO learner's cost GAE; the reward keeps ``ppo.gamma``."""
    from crllk.algos.ppo_lagrangian import PPOLagrangian
    from crllk.config import validate
    from crllk.training.compose import compose_config

    actor, critic, cost_critics = _networks()
    for overrides, cost_gamma in (([], 0.95), (["ppo.cost_gamma=0.99"], 0.99)):
        config = validate(compose_config(["task=small_loop", *overrides]))
        learner = PPOLagrangian(config, actor, {"reward": critic, **cost_critics}, list(_COSTS))
        assert float(learner.advantages.reward.gamma) == pytest.approx(0.95)
        for name in _COSTS:
            assert float(learner.advantages.costs[name].gamma) == pytest.approx(cost_gamma)


def test_gae_helper_feeds_the_loss_with_renamed_keys():
    actor, critic, cost_critics = _networks()
    loss = CriticsPPOLoss(actor, critic, cost_critics)
    loss.set_keys(value_target_lane="ret_lane", value_target_collision="ret_collision")
    modules = make_advantage_modules(0.95, 0.95, critic, cost_critics, loss=loss)
    g = torch.Generator().manual_seed(3)
    shape = (2, 5)  # two environments, five steps
    end = torch.zeros(*shape, 1, dtype=torch.bool)
    td = TensorDict(
        {
            "observation": torch.randn(*shape, _OBS_DIM, generator=g),
            "action": torch.randint(0, _N_ACTIONS, shape, generator=g),
            "next": {
                "observation": torch.randn(*shape, _OBS_DIM, generator=g),
                "reward": torch.rand(*shape, 1, generator=g),
                "cost_lane": torch.rand(*shape, 1, generator=g),
                "cost_collision": torch.zeros(*shape, 1),
                "done": end,
                "terminated": end,
            },
        },
        shape,
    )
    with torch.no_grad():
        td["action_log_prob"] = actor.get_dist(td).log_prob(td["action"])
    modules(td)
    assert {"advantage_reward", "advantage_lane", "ret_lane", "ret_collision"} <= set(td.keys())
    out = loss(LagrangianAdvantage(_COSTS, lagrange=(1.0, 1.0))(td))
    assert all(torch.isfinite(out[key]) for key in _LOSS_KEYS)


# ---------------------------------------------------------------------- (f) continuous actions


def test_continuous_actions_give_finite_losses():
    actor, critic, cost_critics = _networks(lambda: _tanh_normal_actor(action_dim=2))
    loss = CriticsPPOLoss(actor, critic, cost_critics)
    g = torch.Generator().manual_seed(2)
    actions = torch.rand(_BATCH, 2, generator=g) * 1.8 - 0.9  # inside (−1, 1)
    td = LagrangianAdvantage(_COSTS, lagrange=(1.0, 4.0))(_batch(actor, actions, g))
    with _seeded(0):  # TanhNormal has no analytic entropy: a one-sample estimate
        out = loss(td)
    for key, value in out.items():
        assert torch.isfinite(value).all(), key
    sum(out[key] for key in _LOSS_KEYS).backward()
    assert _has_gradient(actor)
    assert all(torch.isfinite(p.grad).all() for p in actor.parameters() if p.grad is not None)


# ---------------------------------------------------------------------- (g) imitation


def test_imitation_term_is_off_by_default_and_needs_no_teacher_key():
    loss, td = _loss()
    assert "teacher_action" not in td
    assert loss(td)["loss_imitation"].item() == 0.0


def test_imitation_term_worked_example():
    """A constant policy with logits (0, log 2, log 5) has probabilities (1/8, 2/8, 5/8); with
    teacher actions 0, 2, 2, 1 and c_I = 0.5 the term is −0.5 · mean(log p)."""
    logits = torch.log(torch.tensor([1.0, 2.0, 5.0]))

    class Constant(nn.Module):
        def forward(self, observation):
            return logits.expand(*observation.shape[:-1], 3)

    actor = ProbabilisticActor(TensorDictModule(Constant(), ["observation"], ["logits"]),
                               in_keys=["logits"], distribution_class=Categorical,
                               return_log_prob=True)
    _, critic, cost_critics = _networks()
    loss = CriticsPPOLoss(actor, critic, cost_critics)
    td = LagrangianAdvantage(_COSTS)(_categorical_batch(_networks()[0])[:4])
    td["action_log_prob"] = actor.get_dist(td).log_prob(td["action"])
    td["teacher_action"] = torch.tensor([0, 2, 2, 1])
    loss.set_imitation_coeff(0.5)
    expected = -0.5 * (torch.log(torch.tensor([1 / 8, 5 / 8, 5 / 8, 2 / 8]))).mean()
    assert loss(td)["loss_imitation"].item() == pytest.approx(expected.item(), rel=1e-6)
    with pytest.raises(ValueError, match="imitation_coeff"):
        loss.set_imitation_coeff(-1.0)
    # the same policy's entropy, −Σ p log p = 0.9003 nats, weighted by the c_H that was set
    probabilities = torch.tensor([1 / 8, 2 / 8, 5 / 8])
    entropy = -(probabilities * probabilities.log()).sum().item()
    assert entropy == pytest.approx(0.9003, abs=1e-4)
    loss.set_entropy_coeff(0.004)
    assert loss(td)["loss_entropy"].item() == pytest.approx(-0.004 * entropy, rel=1e-6)
    with pytest.raises(ValueError, match="entropy_coeff"):
        loss.set_entropy_coeff(float("nan"))


def test_continuous_imitation_trains_the_mean_only():
    """Worked example: a tanh-Gaussian with loc 0 and scale 0.5 and a teacher action tanh(1)
    gives −log π = ½(1/0.5)² + log(0.5·√(2π)) + log(1 − tanh²(1)) per dimension; the gradient
    reaches loc, −c_I (1 − 0)/0.5² per dimension, and not the scale."""
    loc = torch.zeros(1, 2, requires_grad=True)
    scale = torch.full((1, 2), 0.5, requires_grad=True)

    class Params(nn.Module):
        def forward(self, observation):
            return loc.expand(observation.shape[0], 2), scale.expand(observation.shape[0], 2)

    actor = ProbabilisticActor(TensorDictModule(Params(), ["observation"], ["loc", "scale"]),
                               in_keys=["loc", "scale"], distribution_class=TanhNormal,
                               return_log_prob=True)
    _, critic, cost_critics = _networks()
    loss = CriticsPPOLoss(actor, critic, cost_critics)
    g = torch.Generator().manual_seed(0)
    td = LagrangianAdvantage(_COSTS)(_batch(actor, torch.zeros(_BATCH, 2), g))
    td["teacher_action"] = torch.full((_BATCH, 2), math.tanh(1.0))
    loss.set_imitation_coeff(0.5)
    term = loss(td)["loss_imitation"]
    per_dimension = 0.5 * (1.0 / 0.5) ** 2 + math.log(0.5 * math.sqrt(2 * math.pi)) \
        + math.log(1.0 - math.tanh(1.0) ** 2)
    assert term.item() == pytest.approx(0.5 * 2 * per_dimension, rel=1e-4)
    term.backward()
    assert scale.grad is None or torch.all(scale.grad == 0)
    assert loc.grad == pytest.approx(torch.full((1, 2), -0.5 * (1.0 / 0.25)), rel=1e-4)


def test_imitation_pulls_the_policy_towards_the_teacher():
    """Gradient steps on the imitation term alone raise the teacher's action probability,
    for categorical and tanh-Gaussian policies (teacher actions on the box edge included)."""
    for factory, teacher in ((_categorical_actor, torch.full((_BATCH,), 1)),
                             (lambda: _tanh_normal_actor(2),
                              torch.tensor([1.0, -0.5]).expand(_BATCH, 2))):
        actor, critic, cost_critics = _networks(factory)
        loss = CriticsPPOLoss(actor, critic, cost_critics)
        g = torch.Generator().manual_seed(3)
        actions = teacher if factory is _categorical_actor else torch.zeros(_BATCH, 2)
        td = LagrangianAdvantage(_COSTS)(_batch(actor, actions, g))
        td["teacher_action"] = teacher
        loss.set_imitation_coeff(1.0)
        optimizer = torch.optim.Adam(actor.parameters(), lr=1e-2)
        before = loss(td)["loss_imitation"].item()
        for _ in range(50):
            optimizer.zero_grad()
            loss(td)["loss_imitation"].backward()
            optimizer.step()
        assert loss(td)["loss_imitation"].item() < before - 0.5
