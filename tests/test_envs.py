"""The batched TorchRL environment: specs, reward and cost keys, done semantics, seeding,
partial resets, and step-for-step agreement with ``crllk.load``. Real MuJoCo throughout."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.envs import RewardSum, TransformedEnv
from torchrl.envs.utils import check_env_specs

import crllk
from crllk.envs.batched import TERMINATIONS, BatchedLaneKeepingEnv, make_env, sub_env_seeds
from crllk.images import box_average

TASK = "small_loop"
NUM_ENVS = 2
SHORT = {"horizon": 20}
COST_KEYS = ("cost_lane", "cost_collision")
"""The default task's cost entries."""
REWARD_KEYS = ("reward", *COST_KEYS)


@pytest.fixture
def build():
    """Build environments and close them (releasing GL contexts) after the test."""
    built: list[BatchedLaneKeepingEnv] = []

    def make(observation: str = "state", action: str = "discrete", seed: int | None = 0,
             overrides: dict | None = None, num_envs: int = NUM_ENVS) -> BatchedLaneKeepingEnv:
        env = make_env(TASK, num_envs=num_envs, observation=observation, action=action,
                       seed=seed, overrides=SHORT if overrides is None else overrides)
        built.append(env)
        return env

    yield make
    for env in built:
        env.close()


def random_actions(env: BatchedLaneKeepingEnv, steps: int, seed: int) -> torch.Tensor:
    """A fixed action sequence ``[steps, N, ...]`` drawn within the env's action spec."""
    generator = torch.Generator().manual_seed(seed)
    n = env.num_envs
    if env.action_type == "discrete":
        return torch.randint(0, 3, (steps, n), generator=generator)
    return torch.rand((steps, n, 2), generator=generator) * 2 - 1


def replay(env: BatchedLaneKeepingEnv, actions: torch.Tensor,
           start: TensorDictBase | None = None) -> TensorDictBase:
    """Step through ``actions`` with TorchRL auto-reset; the transitions stacked ``[N, T]``."""
    tensordict = env.reset() if start is None else start
    steps = []
    for action in actions:
        tensordict["action"] = action
        step, tensordict = env.step_and_maybe_reset(tensordict)
        steps.append(step)
    return torch.stack(steps, dim=1)


@pytest.mark.parametrize(("observation", "action"),
                         list(itertools.product(("state", "pixels"), ("discrete", "continuous"))))
def test_specs_match_data(build, observation, action):
    """TorchRL's own spec check passes for every observation and action type."""
    env = build(observation, action)
    check_env_specs(env)
    assert env.batch_size == torch.Size([NUM_ENVS])
    assert set(env.reward_keys) == set(REWARD_KEYS)
    observed = set(env.observation_spec.keys(True, True))
    assert observed == {observation, "termination"}  # the reason is information, not an input
    assert not observed & set(REWARD_KEYS), "costs must never be observed"


def test_rollout_reward_and_costs(build):
    """Reward and both costs come per step as finite [N, T, 1]; costs are non-negative."""
    env = build("state", "continuous")
    data = env.rollout(50, break_when_any_done=False)
    assert data.batch_size == torch.Size([NUM_ENVS, 50])
    for key in REWARD_KEYS:
        value = data["next", key]
        assert value.shape == (NUM_ENVS, 50, 1) and value.dtype == torch.float32
        assert torch.isfinite(value).all()
    assert (data["next", "cost_lane"] >= 0).all()
    assert set(data["next", "cost_collision"].unique().tolist()) <= {0.0, 1.0}
    assert data["next", "truncated"].sum() >= NUM_ENVS * 2, "horizon 20 truncates twice in 50"


def test_standing_still_is_truncated_not_terminated(build):
    """At the time limit the episode is truncated; nothing terminates a robot at rest."""
    env = build("state", "duty", overrides={"horizon": 10})
    data = env.rollout(10, policy=lambda td: td.set("action", torch.zeros(NUM_ENVS, 2)),
                       break_when_any_done=False)
    truncated, terminated = data["next", "truncated"], data["next", "terminated"]
    assert truncated[:, -1].all() and not truncated[:, :-1].any()
    assert not terminated.any()
    assert not data["next", "termination"].any()
    assert torch.equal(data["next", "done"], truncated)
    assert torch.allclose(data["next", "reward"], torch.zeros(()), atol=1e-3)


def test_termination_is_not_truncation(build):
    """Driving a hard circle leaves the road: terminated, not truncated, cost_collision 1."""
    env = build("state", "continuous", overrides={"horizon": 200}, num_envs=4)
    data = env.rollout(200, policy=lambda td: td.set("action", torch.tensor([[1.0, -1.0]] * 4)),
                       break_when_any_done=False)
    terminated = data["next", "terminated"]
    assert terminated.any()
    assert not (terminated & data["next", "truncated"]).any()
    assert torch.equal(data["next", "cost_collision"].bool(), terminated)
    reasons = data["next", "termination"]
    assert torch.equal(reasons > 0, terminated)
    assert {TERMINATIONS[k] for k in reasons[terminated].tolist()} == {"off_road"}


@pytest.mark.parametrize(("observation", "action", "steps"),
                         [("state", "discrete", 30), ("state", "continuous", 30),
                          ("pixels", "discrete", 8)])
def test_sub_envs_match_crllk_load(build, observation, action, steps):
    """Sub-environment i replays ``crllk.load(seed=sub_env_seeds(seed, N)[i])`` step for step,
    through time-limit resets (horizon 12)."""
    env = build(observation, action, seed=7, overrides={"horizon": 12})
    actions = random_actions(env, steps, seed=1)
    data = replay(env, actions)
    for i, sub_seed in enumerate(sub_env_seeds(7, NUM_ENVS)):
        expected = dm_control_replay(observation, action, sub_seed, actions[:, i])
        got = data[i]
        for key in (*REWARD_KEYS, observation):
            np.testing.assert_array_equal(got["next", key].numpy(), expected[key], err_msg=key)
        np.testing.assert_array_equal(got["next", "done"].numpy()[:, 0], expected["done"])


def dm_control_replay(observation: str, action: str, seed: int,
                      actions: torch.Tensor) -> dict[str, np.ndarray]:
    """Per-step outputs of ``crllk.load`` under ``actions``, reset after every last step."""
    env = crllk.load(TASK, observation=observation, action=action, seed=seed,
                     overrides={"horizon": 12})
    env.reset()
    out: dict[str, list] = {key: [] for key in (*REWARD_KEYS, observation, "done")}
    for a in actions.numpy():
        ts = env.step(a)
        out["reward"].append([ts.reward])
        for key in (*COST_KEYS, observation):
            out[key].append(np.atleast_1d(ts.observation[key]))
        out["done"].append(ts.last())
        if ts.last():
            env.reset()
    env.physics.free_renderers()
    dtypes = {"done": bool, "pixels": np.uint8}
    return {key: np.asarray(value, dtype=dtypes.get(key, np.float32))
            for key, value in out.items()}


def test_same_seed_same_rollout_and_seeds_differ(build):
    """Same seed: identical data; another seed or another sub-environment: another spawn."""
    a, b, c = build(seed=3), build(seed=3), build(seed=4)
    actions = random_actions(a, 25, seed=0)
    assert (replay(a, actions) == replay(b, actions)).all()
    first_a, first_c = a.reset()["state"], c.reset()["state"]
    assert not torch.equal(first_a, first_c)
    assert not torch.equal(first_a[0], first_a[1])


def test_set_seed_reseeds(build):
    """``set_seed(s)`` then ``reset`` gives the spawns of a fresh env built with seed ``s``."""
    env, fresh = build(seed=0), build(seed=5)
    env.rollout(5)
    env.set_seed(5)
    assert env.seeds == sub_env_seeds(5, NUM_ENVS)
    assert torch.equal(env.reset()["state"], fresh.reset()["state"])


def test_partial_reset_resets_only_flagged_envs(build):
    """A ``"_reset"`` mask restarts the flagged sub-environments and leaves the others be:
    they go on exactly as in a twin env that was not reset."""
    env, twin = build(seed=2, overrides={"horizon": 100}), build(seed=2,
                                                                 overrides={"horizon": 100})
    actions = random_actions(env, 10, seed=3)
    replay(env, actions[:5])
    current = replay(twin, actions[:5])[:, -1].get("next").exclude(*REWARD_KEYS)
    flagged = current.clone().set("_reset", torch.tensor([[True], [False]]))
    after = env.reset(flagged)  # updates ``flagged`` in place, as TorchRL does
    assert env.step_counts.tolist() == [0, 5]
    assert "_reset" not in after
    assert not torch.equal(after["state"][0], current["state"][0])
    assert torch.equal(after["state"][1], current["state"][1])
    tail_env = replay(env, actions[5:], start=after)
    tail_twin = replay(twin, actions[5:], start=current)
    assert torch.equal(tail_env[1]["next", "state"], tail_twin[1]["next", "state"])
    assert not torch.equal(tail_env[0]["next", "state"], tail_twin[0]["next", "state"])


def test_reward_sum_tracks_costs(build):
    """Costs are reward-like keys, so ``RewardSum`` sums them per episode."""
    env = TransformedEnv(build(), RewardSum(in_keys=list(REWARD_KEYS)))
    data = env.rollout(5)
    for key in REWARD_KEYS:
        assert torch.allclose(data["next", f"episode_{key}"][:, -1],
                              data["next", key].sum(1), atol=1e-5)


def test_bad_arguments_are_rejected():
    """Unknown observation or action types and an empty batch fail clearly."""
    with pytest.raises(ValueError, match="observation"):
        make_env(TASK, observation="lidar")
    with pytest.raises(ValueError, match="action"):
        make_env(TASK, observation="state", action="joystick")
    with pytest.raises(ValueError, match="num_envs"):
        make_env(TASK, observation="state", num_envs=0)


def test_reset_output_is_a_tensordict(build):
    """A full reset returns every sub-environment's first observation, not done."""
    env = build()
    first = env.reset()
    assert isinstance(first, TensorDict)
    assert not first["done"].any() and env.step_counts.tolist() == [0] * NUM_ENVS


def test_make_env_is_exported_lazily():
    """`crllk.make_env` is the batched environment factory of crllk.envs.batched."""
    import crllk
    from crllk.envs.batched import make_env

    assert crllk.make_env is make_env


@pytest.mark.parametrize("factor", [2, 3, 4, 5, 16])
def test_box_average_is_the_rounded_float_mean(factor):
    """The integer downsampling of camera images gives exactly the rounded float32 block mean,
    including every 2x2 block sum that rounds half up."""
    rng = np.random.default_rng(factor)
    image = rng.integers(0, 256, (6 * factor, 8 * factor, 3), dtype=np.uint8)
    image[:factor, :, :] = rng.choice([0, 1, 2, 254, 255], (factor, 8 * factor, 3))
    blocks = image.reshape(6, factor, 8, factor, 3)
    expected = (blocks.mean(axis=(1, 3), dtype=np.float32) + 0.5).astype(np.uint8)
    np.testing.assert_array_equal(box_average(image, factor), expected)


def test_privileged_state_rides_along_with_pixels():
    """Pixels with ``privileged_state`` also carry the ``state`` features, equal to those of a
    state env driven by the same seed and actions; the specs still check out."""
    pixels = make_env(TASK, num_envs=NUM_ENVS, observation="pixels", seed=3, overrides=SHORT,
                      privileged_state=True)
    state = make_env(TASK, num_envs=NUM_ENVS, observation="state", seed=3, overrides=SHORT)
    try:
        td_pixels, td_state = pixels.reset(), state.reset()
        torch.testing.assert_close(td_pixels["state"], td_state["state"])
        actions = torch.tensor([0, 2])
        for _ in range(5):
            td_pixels = pixels.step(td_pixels.set("action", actions))["next"]
            td_state = state.step(td_state.set("action", actions))["next"]
            torch.testing.assert_close(td_pixels["state"], td_state["state"])
        assert td_pixels["pixels"].dtype == torch.uint8
        check_env_specs(pixels, seed=None)
    finally:
        pixels.close()
        state.close()


def test_commands_are_the_duties_in_flight(build):
    """``"commands"`` holds the duty pairs of the last steps, newest first; a discrete left
    turn shows up as (0.04, 0.4) at the front, and the specs hold."""
    env = make_env(TASK, num_envs=2, observation="pixels", action="discrete", seed=0,
                   overrides=SHORT, commands=True)
    check_env_specs(env, seed=0)
    td = env.reset()
    assert td["commands"].shape == (2, 10) and not td["commands"].any()
    td["action"] = torch.tensor([0, 2])
    nxt = env.step(td)["next"]
    assert nxt["commands"][0, :2].tolist() == pytest.approx([0.04, 0.4])
    assert nxt["commands"][1, :2].tolist() == pytest.approx([0.3, 0.3])
    assert not nxt["commands"][:, 2:].any()
    env.close()
