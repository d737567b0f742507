"""Networks: shapes, the paper's CNN size, fixed feature scales, shared critic heads."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Bounded, Categorical

from crllk.rl.models import (
    ModelConfig,
    make_actor,
    make_critic,
    make_shared_critic,
    original_pixel_trunk,
    state_feature_scales,
)

IMAGE = (30, 40, 3)


def test_original_cnn_flattens_to_6912_features_at_30x40():
    convs = original_pixel_trunk(IMAGE, 256)[0]
    assert convs(torch.zeros(1, 3, 30, 40)).shape == (1, 6912)


@pytest.mark.parametrize("encoder", ["fast", "original"])
def test_pixel_actor_and_critic_keep_leading_batch_dimensions(encoder):
    config = ModelConfig(encoder=encoder)
    actor = make_actor("pixels", IMAGE, "discrete", Categorical(3), config)
    critic = make_critic("pixels", IMAGE, config)
    td = TensorDict({"pixels": torch.randint(0, 256, (2, 5, *IMAGE), dtype=torch.uint8)},
                    batch_size=[2, 5])
    actor(td)
    critic(td)
    assert td["action"].shape == (2, 5) and td["action"].max() < 3
    assert td["action_log_prob"].shape == (2, 5)
    assert td["state_value"].shape == (2, 5, 1)


def test_continuous_actor_stays_in_bounds_and_starts_with_the_configured_spread():
    spec = Bounded(-1.0, 1.0, shape=(2,))
    actor = make_actor("state", (4,), "continuous", spec, ModelConfig(initial_log_std=-1.0))
    td = TensorDict({"state": torch.randn(4096, 4) * 100}, batch_size=[4096])
    actor(td)
    assert td["action"].abs().max() <= 1.0
    assert torch.allclose(td["scale"], torch.full_like(td["scale"], torch.exp(torch.tensor(-1.0))))


def test_continuous_actor_spread_is_held_at_its_bound_which_then_gets_no_gradient():
    spec = Bounded(-1.0, 1.0, shape=(2,))
    actor = make_actor("state", (4,), "continuous", spec,
                       ModelConfig(initial_log_std=-0.5, max_log_std=-0.7))
    params = actor.module[0].module
    with torch.no_grad():
        params.log_std.copy_(torch.tensor([-0.9, 0.3]))  # one below the bound, one above
    td = TensorDict({"state": torch.randn(8, 4)}, batch_size=[8])
    actor(td)
    assert td["scale"][0].tolist() == pytest.approx([math.exp(-0.9), math.exp(-0.7)])
    td["scale"].sum().backward()
    assert params.log_std.grad[0] > 0 and params.log_std.grad[1] == 0
    unbounded = make_actor("state", (4,), "continuous", spec, ModelConfig())
    with torch.no_grad():
        unbounded.module[0].module.log_std.fill_(0.3)
    unbounded(td)
    assert td["scale"].max().item() == pytest.approx(math.exp(0.3))


@pytest.mark.parametrize("observation, shape", [("state", (4,)), ("pixels", IMAGE)])
def test_a_state_dependent_spread_starts_at_its_initial_value_and_learns_per_state(
        observation, shape):
    """With ``state_dependent_std`` the spread is a head of the network: about
    ``initial_log_std`` everywhere at first, then different observations get different
    spreads; it stays within its bounds, and no gradient flows where it is held."""
    spec = Bounded(-1.0, 1.0, shape=(2,))
    config = ModelConfig(initial_log_std=-0.5, state_dependent_std=True, max_log_std=0.5)
    actor = make_actor(observation, shape, "continuous", spec, config)
    assert not hasattr(actor.module[0].module, "log_std")
    inputs = (torch.randn(8, *shape) if observation == "state"
              else torch.randint(0, 256, (8, *shape), dtype=torch.uint8))
    td = TensorDict({observation: inputs}, batch_size=[8])
    actor(td)
    assert td["scale"].shape == (8, 2)
    assert td["scale"].log().sub(-0.5).abs().max() < 0.05
    head = [m for m in actor.module[0].module.modules() if isinstance(m, torch.nn.Linear)][-1]
    assert head.out_features == 4
    with torch.no_grad():  # the spread's half of the head reads its input now
        head.weight[2:].normal_(0.0, 0.05)
    actor(td)
    spreads = td["scale"].log()
    assert spreads.std(dim=0).min() > 1e-3  # per observation
    assert spreads.min() >= -5.0 - 1e-6 and spreads.max() <= 0.5 + 1e-6
    with torch.no_grad():
        head.bias[2:].fill_(10.0)  # far above the bound
    actor(td)
    assert torch.allclose(td["scale"], torch.full_like(td["scale"], math.exp(0.5)))
    td["scale"].sum().backward()
    assert head.bias.grad[2:].abs().max() == 0
    with torch.no_grad():
        head.bias[2:].fill_(-10.0)  # far below the range
    actor(td)
    assert torch.allclose(td["scale"], torch.full_like(td["scale"], math.exp(-5.0)))


def test_state_features_are_scaled_by_name():
    scales = state_feature_scales(["lateral_offset", "yaw_rate", "duty_left_t-0", "unknown"])
    assert scales.tolist() == pytest.approx([0.1, 1.5, 0.5, 1.0])
    critic = make_critic("state", (4,), ModelConfig(), feature_names=[
        "lateral_offset", "yaw_rate", "duty_left_t-0", "unknown"])
    scale_layer = critic.module[0][0]
    assert scale_layer(torch.tensor([0.05, 3.0, 0.25, 7.0])).tolist() == pytest.approx(
        [0.5, 2.0, 0.5, 7.0])
    with pytest.raises(ValueError, match="feature names"):
        make_critic("state", (3,), ModelConfig(), feature_names=["lateral_offset"])


def test_shared_critic_writes_one_value_per_head_from_one_encoder():
    keys = ["state_value", "state_value_lane", "state_value_collision"]
    critic = make_shared_critic("pixels", IMAGE, ModelConfig(), keys)
    calls = []
    critic.module.encoder.register_forward_hook(lambda *args: calls.append(1))
    td = TensorDict({"pixels": torch.zeros((3, *IMAGE), dtype=torch.uint8)}, batch_size=[3])
    critic(td)
    assert len(calls) == 1
    assert all(td[k].shape == (3, 1) for k in keys)
    assert not torch.equal(td["state_value"], td["state_value_lane"]) or \
        critic.module.head.weight.abs().sum() == 0


def test_loss_runs_a_shared_critic_once_per_batch():
    from crllk.rl.loss import CriticsPPOLoss

    keys = ["state_value", "state_value_lane", "state_value_collision"]
    critic = make_shared_critic("state", (4,), ModelConfig(), keys)
    actor = make_actor("state", (4,), "discrete", Categorical(3), ModelConfig())
    loss = CriticsPPOLoss(actor, critic, {"lane": critic, "collision": critic})
    calls = []
    critic.module.encoder.register_forward_hook(lambda *args: calls.append(1))
    n = 8
    td = TensorDict({"state": torch.randn(n, 4)}, batch_size=[n])
    with torch.no_grad():
        actor(td)
    for key in ("advantage", "value_target", "advantage_lane", "value_target_lane",
                "advantage_collision", "value_target_collision"):
        td[key] = torch.randn(n, 1)
    out = loss(td)
    assert len(calls) == 1
    sum(out[k] for k in ("loss_objective", "loss_critic", "loss_cost_critic")).backward()
    assert critic.module.head.weight.grad.abs().sum(dim=1).gt(0).all()  # every head learns


@pytest.mark.parametrize("action", ["discrete", "continuous"])
def test_pixel_actor_with_commands_reads_them(action):
    """With commands_dim the actor reads "commands" too: changing only the commands changes
    the action distribution."""
    spec = Categorical(3) if action == "discrete" else Bounded(-1.0, 1.0, shape=(2,))
    torch.manual_seed(0)
    actor = make_actor("pixels", IMAGE, action, spec, ModelConfig(), commands_dim=10)
    pixels = torch.randint(0, 256, (4, *IMAGE), dtype=torch.uint8)
    dists = []
    for value in (0.0, 0.8):
        td = TensorDict({"pixels": pixels, "commands": torch.full((4, 10), value)}, [4])
        dists.append(actor.get_dist(td))
    if action == "discrete":
        assert not torch.allclose(dists[0].logits, dists[1].logits)
    else:
        assert not torch.allclose(dists[0].deterministic_sample, dists[1].deterministic_sample)
    with pytest.raises(KeyError):
        actor(TensorDict({"pixels": pixels}, [4]))


@pytest.mark.parametrize("overrides, message", [
    (["model.initial_log_std=2"], "model.initial_log_std: must lie in [-5.0, 1.0]"),
    (["model.initial_log_std=-6"], "model.initial_log_std: must lie in [-5.0, 1.0]"),
    (["model.max_log_std=-1", "model.initial_log_std=-0.5"],
     "model.initial_log_std: must lie in [-5.0, -1.0]"),
    (["model.max_log_std=-6"], "model.max_log_std: must be at least -5.0")])
def test_a_state_dependent_spread_refuses_a_start_outside_its_bounds(overrides, message):
    """Outside its bounds the spread would be held from the first step and never learn."""
    from crllk.config import validate
    from crllk.errors import ConfigError
    from crllk.training.compose import compose_config

    base = ["obs=state", "agent=CRLLK-C", "model.state_dependent_std=true"]
    with pytest.raises(ConfigError) as caught:
        validate(compose_config([*base, *overrides]))
    assert message in str(caught.value) and "\n" not in str(caught.value)
    validate(compose_config(overrides))  # the learned parameter takes any start
