"""Networks run without tensordict's wrappers (:mod:`crllk.rl.direct`): what the wrappers
write, bit for bit, on the project's networks; anything else falls back to the wrappers."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule, TensorDictSequential
from torchrl.data import Bounded, Categorical

from crllk.rl.direct import actor_distribution, is_plain, run_module
from crllk.rl.models import ModelConfig, make_actor, make_critic, make_shared_critic

STATE = (6,)


def _batch() -> TensorDict:
    generator = torch.Generator().manual_seed(2)
    return TensorDict({"state": torch.randn(16, *STATE, generator=generator),
                       "commands": torch.randn(16, 4, generator=generator)}, batch_size=[16])


@pytest.mark.parametrize("action, config, commands", [
    ("discrete", ModelConfig(), 0),
    ("continuous", ModelConfig(), 0),
    ("continuous", ModelConfig(state_dependent_std=True), 0),
    ("discrete", ModelConfig(policy_commands=True), 4)])
def test_the_actor_s_distribution_is_get_dist_s(action, config, commands):
    spec = Categorical(3) if action == "discrete" else Bounded(-1.0, 1.0, shape=(2,))
    actor = make_actor("state", STATE, action, spec, config, commands_dim=commands)
    assert is_plain(actor.module[0])  # the direct path is the one compared
    ours, theirs = _batch(), _batch()
    ours_dist = actor_distribution(actor, ours)
    theirs_dist = actor.get_dist(theirs)
    assert set(ours.keys()) == set(theirs.keys())
    for key in list(theirs.keys()):
        assert torch.equal(ours[key], theirs[key]), key
    sample = theirs_dist.sample()
    assert torch.equal(ours_dist.log_prob(sample), theirs_dist.log_prob(sample))


def test_critics_write_what_their_wrappers_write():
    single = make_critic("state", STATE, ModelConfig(), out_key="state_value_lane")
    shared = make_shared_critic("state", STATE, ModelConfig(),
                                ["state_value", ("costs", "lane"), ("costs", "collision")])
    for critic in (single, shared):
        assert is_plain(critic)
        ours, theirs = _batch(), _batch()
        run_module(critic, ours)
        critic(theirs)
        assert set(ours.keys(True)) == set(theirs.keys(True))
        for key in theirs.keys(True, True):
            assert torch.equal(ours[key], theirs[key]), key


def test_other_modules_run_through_their_wrappers():
    """Keyword inputs (whose order is not the keys'), a sequence of modules and an out-of-place
    module are left to tensordict, and give what it gives."""

    class Difference(torch.nn.Module):
        def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
            return a - b

    keyword = TensorDictModule(Difference(), in_keys={"b": "y", "a": "x"}, out_keys=["z"])
    chain = TensorDictSequential(TensorDictModule(torch.nn.Identity(), in_keys=["x"],
                                                  out_keys=["w"]))
    copying = TensorDictModule(torch.nn.Identity(), in_keys=["x"], out_keys=["v"],
                               inplace=False)
    hooked = TensorDictModule(torch.nn.Identity(), in_keys=["x"], out_keys=["u"])
    hooked.register_forward_hook(lambda module, inputs, output: output)
    selected = TensorDictModule(_Pair(), in_keys=["x"], out_keys=["p", "q"]).select_out_keys("q")
    reading = TensorDictModule(torch.nn.Identity(), in_keys=["x"], out_keys=["r"],
                               get_kwargs={"default": None})
    for module in (keyword, chain, copying, hooked, selected, reading):
        assert not is_plain(module)
    td = TensorDict({"x": torch.ones(3), "y": torch.zeros(3)}, batch_size=[3])
    run_module(keyword, td)
    assert td["z"].tolist() == [1.0, 1.0, 1.0]  # a − b with a = x, b = y
    run_module(chain, td)
    assert torch.equal(td["w"], td["x"])
    run_module(copying, td)
    assert "v" not in set(td.keys())  # the copy got it, as module(td) leaves it
    run_module(selected, td)
    assert "q" in set(td.keys()) and "p" not in set(td.keys())


class _Pair(torch.nn.Module):
    """Two outputs, of which a module may select one."""

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return x, 2 * x
