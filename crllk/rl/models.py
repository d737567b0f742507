"""Policy and value networks: encoders for camera pixels and lane-relative state, heads on top.

Every network reads one observation key and owns its encoder (no shared trunk), so the actor,
the reward critic and each cost critic can be trained, checkpointed and exported on their own.

Encoders map an observation to a feature vector:

- ``"fast"`` (pixels, default): three strided convolutions (16, 32, 32 channels) on the 30×40
  camera image, then a 256-unit layer; about 2 MFLOP per image.
- ``"original"`` (pixels): the CRLLK paper's network, 3×3 convolutions 32-32-32, max-pool,
  64-64-64, max-pool, a 2×2 convolution to 128 channels, a 256-unit sigmoid layer; about
  100 MFLOP per image at 30×40.
- ``"mlp"`` (state): two tanh layers.

Pixels arrive as uint8 ``[*B, H, W, 3]`` (channels last, as the environment delivers them) and
are scaled to [0, 1] inside the encoder.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torch.distributions import Categorical
from torchrl.data import Categorical as CategoricalSpec
from torchrl.data import TensorSpec
from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator

from crllk.rl.model_config import STATE_LOG_STD_RANGE, ModelConfig
from crllk.tasks.actions import DISCRETE_DUTIES, GAUSSIAN_ACTIONS, POLICY_ACTIONS

PIXEL_SCALE = 1.0 / 255.0  # uint8 camera value -> [0, 1]


class PixelScale(nn.Module):
    """uint8 ``[*B, H, W, C]`` -> float ``[N, C, H, W]`` in [0, 1], with the batch flattened."""

    def forward(self, pixels: torch.Tensor) -> torch.Tensor:
        images = pixels.reshape(-1, *pixels.shape[-3:]).permute(0, 3, 1, 2)
        return images.to(torch.float32) * PIXEL_SCALE


class PixelEncoder(nn.Module):
    """A convolutional encoder on camera images; restores the leading batch dimensions."""

    def __init__(self, trunk: nn.Module, image_shape: Sequence[int]):
        super().__init__()
        self.scale = PixelScale()
        self.trunk = trunk
        with torch.no_grad():
            probe = torch.zeros((1, *image_shape), dtype=torch.uint8)
            self.output_dim = int(self.trunk(self.scale(probe)).shape[-1])

    def forward(self, pixels: torch.Tensor) -> torch.Tensor:
        features = self.trunk(self.scale(pixels))
        return features.reshape(*pixels.shape[:-3], features.shape[-1])


def fast_pixel_trunk(image_shape: Sequence[int], feature_dim: int) -> nn.Module:
    """Three stride-2 convolutions and one dense layer (ReLU)."""
    height, width, channels = image_shape
    convs = nn.Sequential(
        nn.Conv2d(channels, 16, kernel_size=5, stride=2, padding=2), nn.ReLU(),
        nn.Conv2d(16, 32, kernel_size=3, stride=2, padding=1), nn.ReLU(),
        nn.Conv2d(32, 32, kernel_size=3, stride=2, padding=1), nn.ReLU(),
        nn.Flatten(),
    )
    with torch.no_grad():
        flat = convs(torch.zeros(1, channels, height, width)).shape[-1]
    return nn.Sequential(convs, nn.Linear(flat, feature_dim), nn.ReLU())


def original_pixel_trunk(image_shape: Sequence[int], feature_dim: int) -> nn.Module:
    """The CRLLK paper's convolutional network (flattens to 6912 features at 30×40)."""
    height, width, channels = image_shape

    def conv(c_in: int, c_out: int, kernel: int = 3) -> list[nn.Module]:
        return [nn.Conv2d(c_in, c_out, kernel_size=kernel, padding="same" if kernel == 3 else 0),
                nn.ReLU()]

    convs = nn.Sequential(
        *conv(channels, 32), *conv(32, 32), *conv(32, 32), nn.MaxPool2d(2),
        *conv(32, 64), *conv(64, 64), *conv(64, 64), nn.MaxPool2d(2),
        *conv(64, 128, kernel=2), nn.Flatten(),
    )
    with torch.no_grad():
        flat = convs(torch.zeros(1, channels, height, width)).shape[-1]
    return nn.Sequential(convs, nn.Linear(flat, feature_dim), nn.Sigmoid())


STATE_FEATURE_SCALES = {  # typical magnitude of each state feature, by name prefix (its units)
    "lateral_offset": 0.1,  # m
    "heading_error": 1.0,  # sin/cos
    "forward_speed": 0.2,  # m/s
    "yaw_rate": 1.5,  # rad/s
    "curvature": 2.5,  # 1/m
    "obstacle_distance": 1.5,  # m
    "obstacle_lateral": 0.1,  # m
    "mover_distance": 1.5,  # m
    "mover_lateral": 0.1,  # m
    "mover_speed": 0.2,  # m/s
    "duty": 0.5,  # duty cycle
}


def state_feature_scales(names: Sequence[str]) -> torch.Tensor:
    """The divisor of each named state feature that brings it to order one."""
    scales = []
    for name in names:
        matches = [v for prefix, v in STATE_FEATURE_SCALES.items() if name.startswith(prefix)]
        scales.append(matches[0] if matches else 1.0)
    return torch.tensor(scales, dtype=torch.float32)


class FeatureScale(nn.Module):
    """Divides each feature by a fixed scale (a buffer, saved with the network)."""

    def __init__(self, scales: torch.Tensor):
        super().__init__()
        self.register_buffer("scales", scales.clone())

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return features / self.scales


def state_encoder(num_features: int, hidden: int,
                  feature_names: Sequence[str] | None = None) -> nn.Module:
    """Two tanh layers on the lane-relative state features, scaled to order one by name."""
    scales = (state_feature_scales(feature_names) if feature_names is not None
              else torch.ones(num_features))
    if scales.numel() != num_features:
        raise ValueError(f"{scales.numel()} feature names for {num_features} features")
    return nn.Sequential(FeatureScale(scales), nn.Linear(num_features, hidden), nn.Tanh(),
                         nn.Linear(hidden, hidden), nn.Tanh())


def make_encoder(observation: str, observation_shape: Sequence[int], config: ModelConfig,
                 feature_names: Sequence[str] | None = None) -> tuple[nn.Module, int]:
    """The encoder for one network and the width of its output."""
    if observation == "state":
        encoder = state_encoder(observation_shape[-1], config.hidden, feature_names)
        return encoder, config.hidden
    if observation != "pixels":
        raise ValueError(f"observation must be 'pixels' or 'state', got {observation!r}")
    image_shape = tuple(observation_shape[-3:])
    if config.encoder == "fast":
        trunk = fast_pixel_trunk(image_shape, config.feature_dim)
    elif config.encoder == "original":
        trunk = original_pixel_trunk(image_shape, config.feature_dim)
    else:
        raise ValueError(f"pixel encoder must be 'fast' or 'original', got {config.encoder!r}")
    encoder = PixelEncoder(trunk, image_shape)
    return encoder, encoder.output_dim


def _head(in_dim: int, out_dim: int, *, gain: float) -> nn.Linear:
    """A linear head with orthogonal weights of the given gain and zero bias."""
    layer = nn.Linear(in_dim, out_dim)
    nn.init.orthogonal_(layer.weight, gain=gain)
    nn.init.zeros_(layer.bias)
    return layer


class GaussianParams(nn.Module):
    """Action means from a head, with a learned state-independent log standard deviation,
    at most ``max_log_std`` when one is given (above it the parameter gets no gradient)."""

    def __init__(self, body: nn.Module, action_dim: int, initial_log_std: float,
                 max_log_std: float | None = None):
        super().__init__()
        self.body = body
        self.log_std = nn.Parameter(torch.full((action_dim,), float(initial_log_std)))
        self.max_log_std = max_log_std

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        loc = self.body(*inputs)
        log_std = (self.log_std if self.max_log_std is None
                   else self.log_std.clamp(max=self.max_log_std))
        return loc, log_std.exp().expand_as(loc)


class StateGaussianParams(nn.Module):
    """Action means and log standard deviations from one head (``body`` gives
    ``2 * action_dim`` outputs): log σ = ``initial_log_std`` + the head's second half, within
    :data:`~crllk.rl.model_config.STATE_LOG_STD_RANGE` and at most ``max_log_std`` (outside,
    no gradient)."""

    def __init__(self, body: nn.Module, action_dim: int, initial_log_std: float,
                 max_log_std: float | None = None):
        super().__init__()
        self.body = body
        self.action_dim = action_dim
        self.initial_log_std = float(initial_log_std)
        low, high = STATE_LOG_STD_RANGE
        self.log_std_bounds = (low, high if max_log_std is None else min(max_log_std, high))

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        loc, offset = self.body(*inputs).split(self.action_dim, dim=-1)
        log_std = (self.initial_log_std + offset).clamp(*self.log_std_bounds)
        return loc, log_std.exp()


COMMANDS_SCALE = 0.5
"""Typical magnitude of a commanded wheel duty (duty cycle), as for the state features."""


class WithCommands(nn.Module):
    """An observation encoder joined by the policy's recent wheel commands: their
    concatenation goes through one tanh layer before ``head``."""

    def __init__(self, encoder: nn.Module, width: int, commands_dim: int, hidden: int,
                 head: nn.Module):
        super().__init__()
        self.encoder = encoder
        self.joint = nn.Sequential(nn.Linear(width + commands_dim, hidden), nn.Tanh())
        self.head = head

    def forward(self, observation: torch.Tensor, commands: torch.Tensor) -> torch.Tensor:
        features = torch.cat([self.encoder(observation), commands / COMMANDS_SCALE], dim=-1)
        return self.head(self.joint(features))


def make_actor(observation: str, observation_shape: Sequence[int], action: str,
               action_spec: TensorSpec, config: ModelConfig,
               feature_names: Sequence[str] | None = None,
               commands_dim: int = 0) -> ProbabilisticActor:
    """The policy: categorical over the three discrete actions, or a tanh-squashed Gaussian
    over (velocity, steering) in [-1, 1]². Writes ``action`` and ``action_log_prob``.
    ``feature_names`` (state observations) choose the fixed input scales. With
    ``commands_dim`` the policy also reads ``"commands"``, its recent wheel duties. A
    discrete policy built for an environment of other actions (its deployed policy plays
    wheel duties, :mod:`crllk.rl.expected_duty`) keeps its own three actions."""
    encoder, width = make_encoder(observation, observation_shape, config, feature_names)
    in_keys = [observation, "commands"] if commands_dim else [observation]

    def body(out_dim: int) -> nn.Module:
        head = _head(config.hidden if commands_dim else width, out_dim, gain=0.01)
        if commands_dim:
            return WithCommands(encoder, width, commands_dim, config.hidden, head)
        return nn.Sequential(encoder, head)

    if action == "discrete":
        if not isinstance(action_spec, CategoricalSpec):
            action_spec = CategoricalSpec(len(DISCRETE_DUTIES), shape=action_spec.shape[:-1],
                                          dtype=torch.int64, device=action_spec.device)
        num_actions = int(action_spec.space.n)
        module = TensorDictModule(body(num_actions), in_keys=in_keys, out_keys=["logits"])
        return ProbabilisticActor(module, in_keys=["logits"], spec=action_spec,
                                  distribution_class=Categorical, return_log_prob=True)
    if action not in GAUSSIAN_ACTIONS:
        raise ValueError(f"action must be one of {', '.join(POLICY_ACTIONS)}, got {action!r}")
    action_dim = int(action_spec.shape[-1])
    if config.state_dependent_std:
        net = StateGaussianParams(body(2 * action_dim), action_dim, config.initial_log_std,
                                  config.max_log_std)
    else:
        net = GaussianParams(body(action_dim), action_dim, config.initial_log_std,
                             config.max_log_std)
    module = TensorDictModule(net, in_keys=in_keys, out_keys=["loc", "scale"])
    low, high = action_spec.space.low, action_spec.space.high
    return ProbabilisticActor(module, in_keys=["loc", "scale"], spec=action_spec,
                              distribution_class=TanhNormal,
                              distribution_kwargs={"low": low, "high": high},
                              return_log_prob=True)


def make_critic(observation: str, observation_shape: Sequence[int], config: ModelConfig,
                out_key: str = "state_value",
                feature_names: Sequence[str] | None = None) -> ValueOperator:
    """A value network reading the observation and writing ``out_key`` (shape [*B, 1])."""
    encoder, width = make_encoder(observation, observation_shape, config, feature_names)
    net = nn.Sequential(encoder, _head(width, 1, gain=1.0))
    return ValueOperator(net, in_keys=[observation], out_keys=[out_key])


class _Heads(nn.Module):
    """One encoder, one linear value head per output, returned as a tuple of [*B, 1]."""

    def __init__(self, encoder: nn.Module, width: int, count: int):
        super().__init__()
        self.encoder = encoder
        self.head = _head(width, count, gain=1.0)

    def forward(self, observation: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return tuple(self.head(self.encoder(observation)).split(1, dim=-1))


def make_shared_critic(observation: str, observation_shape: Sequence[int], config: ModelConfig,
                       out_keys: Sequence[str],
                       feature_names: Sequence[str] | None = None) -> ValueOperator:
    """Value networks sharing one encoder: one head per key of ``out_keys`` (the reward's and
    each cost's), so a pixel encoder runs once for all of them."""
    encoder, width = make_encoder(observation, observation_shape, config, feature_names)
    return ValueOperator(_Heads(encoder, width, len(out_keys)), in_keys=[observation],
                         out_keys=list(out_keys))


__all__ = ["ModelConfig", "make_actor", "make_critic",
           "make_encoder", "make_shared_critic"]
