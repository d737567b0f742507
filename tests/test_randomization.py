"""Per-episode domain randomisation (``randomize``): seeded draws within their ranges, visible
in the images, the camera pose and the motion, restored exactly from snapshots, nothing changed
when it is off, and the camera effects of a batch of frames exactly those of each frame alone."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDictBase
from test_env_state import assert_identical, drive, random_actions

from crllk.envs.batched import BatchedLaneKeepingEnv, make_env, sub_env_seeds
from crllk.errors import ConfigError
from crllk.sim import constants as C
from crllk.sim.camera_effects import (
    FrameEffects,
    add_noise,
    add_noise_frames,
    apply_effects,
    compress,
    compress_frames,
    noise_bank,
    quantisation_steps,
)
from crllk.sim.motor import MotorConfig
from crllk.sim.physics import Physics
from crllk.sim.variation import SceneVariation
from crllk.tasks.config import load_task_config
from crllk.tasks.lane_keeping import load
from crllk.tasks.randomization import DISTRACTOR_HALF_SIDES, PRESETS, draw_variation

DATA = Path(__file__).parent / "data"
DEFAULT = {"randomize": "default", "horizon": 30}


@pytest.fixture
def build():
    built: list[BatchedLaneKeepingEnv] = []

    def make(overrides=None, observation="pixels", num_envs=2, seed=0, task="small_loop"):
        env = make_env(task, num_envs=num_envs, observation=observation, seed=seed,
                       overrides=overrides or {"horizon": 30})
        built.append(env)
        return env

    yield make
    for env in built:
        env.close()


def test_same_seed_same_draws_and_images(build):
    a, b = build(DEFAULT, seed=7), build(DEFAULT, seed=7)
    first, second = a.reset(), b.reset()
    assert [t.episode.variation for t in a.tasks] == [t.episode.variation for t in b.tasks]
    assert torch.equal(first["pixels"], second["pixels"])
    generator = torch.Generator().manual_seed(1)
    actions = random_actions(a, 12, generator)
    got, _ = drive(a, actions, first)
    expected, _ = drive(b, actions, second)
    assert_identical(got, expected, "pixels")


def test_episodes_differ(build):
    env = build(DEFAULT, num_envs=3)
    env.reset()
    variations = [t.episode.variation for t in env.tasks]
    assert variations[0] != variations[1] != variations[2]
    env.reset()
    assert [t.episode.variation for t in env.tasks] != variations


def test_draws_stay_within_their_ranges():
    config, motor, random = PRESETS["default"], MotorConfig(), np.random.RandomState(0)
    draws = [draw_variation(config, motor, 3, random) for _ in range(500)]

    def within(values, bounds, scale=1.0):
        values = np.asarray(values, dtype=float)
        assert values.min() >= bounds[0] * scale - 1e-12
        assert values.max() <= bounds[1] * scale + 1e-12
        assert values.max() - values.min() > 0.5 * (bounds[1] - bounds[0]) * scale

    within([d.light_intensity for d in draws], config.light_intensity)
    within([math.acos(-d.light_direction[2]) for d in draws], config.light_tilt)
    within([d.ambient for d in draws], config.ambient)
    within([d.headlight for d in draws], config.headlight)
    within([d.floor_color for d in draws], config.floor_color)
    within([d.horizon_color for d in draws], config.horizon_color)
    within([d.object_colors for d in draws], config.object_color)
    within([d.camera_height for d in draws], config.camera_height, C.CAMERA_HEIGHT)
    within([d.camera_pitch for d in draws], config.camera_pitch, C.CAMERA_PITCH)
    within([d.camera_fovy for d in draws], config.camera_fov, C.CAMERA_FOVY)
    noise = config.camera_position_noise
    within([d.camera_offset for d in draws], (-noise, noise))
    within([d.jpeg_quality for d in draws], config.jpeg_quality)
    within([d.noise_std for d in draws], config.sensor_noise)
    within([d.motor.max_speed for d in draws], config.max_speed, motor.max_speed)
    low = motor.yaw_rate_per_duty * config.yaw_rate[0] / config.wheel_distance[1]
    high = motor.yaw_rate_per_duty * config.yaw_rate[1] / config.wheel_distance[0]
    within([d.motor.yaw_rate_per_duty for d in draws], (low, high))
    within([d.motor.linear_time_constant for d in draws], config.time_constants,
           motor.linear_time_constant)
    within([d.motor.delay - motor.delay for d in draws], config.delay)
    trims = np.array([d.trim for d in draws])
    assert abs(trims.std() - config.trim) < 0.2 * config.trim


def test_appearance_changes_the_image_and_camera_pose(build):
    plain, randomized = build(seed=4), build(DEFAULT, seed=4)
    plain.reset()
    randomized.reset()
    for k in range(2):  # the same spawn pose: drawn before the randomisation
        assert plain.physics[k].pose() == randomized.physics[k].pose()
        camera = C.CAMERA
        assert not np.allclose(plain.physics[k].named.data.cam_xpos[camera],
                               randomized.physics[k].named.data.cam_xpos[camera], atol=1e-4)
    images = plain._observations, randomized._observations
    assert np.abs(images[0].astype(int) - images[1]).mean() > 5


def test_dynamics_change_the_motion():
    def drive_straight(overrides):
        env = load("small_loop", observation="state", action="duty", seed=2, overrides=overrides)
        env.reset()
        for _ in range(30):
            env.step(np.array([0.5, 0.5]))
        return env.physics.pose(), env.physics.forward_speed()

    appearance_only = {"randomize": {"preset": "default", "max_speed": None, "yaw_rate": None,
                                     "wheel_distance": None, "time_constants": None,
                                     "delay": None, "trim": 0}}
    nominal = drive_straight(None)
    assert drive_straight(appearance_only) == nominal
    (_, _, yaw), speed = drive_straight({"randomize": "default"})
    assert abs(speed - nominal[1]) > 1e-3 or abs(yaw - nominal[0][2]) > 1e-3


def test_restored_env_steps_identically_with_randomization(build):
    original = build(DEFAULT, num_envs=2)
    generator = torch.Generator().manual_seed(3)
    _, carried = drive(original, random_actions(original, 20, generator), original.reset())
    snapshot = original.sim_state()
    tail = random_actions(original, 25, generator)
    expected, _ = drive(original, tail, carried.clone())
    assert expected["next", "done"].any(), "a reset happens after the snapshot"
    restored = build(DEFAULT, num_envs=2, seed=99)
    restored.reset()
    restored.load_sim_state(snapshot)
    got, _ = drive(restored, tail, carried.clone())
    assert_identical(got, expected, "pixels")


@pytest.mark.parametrize("task", ["traffic_loop", "pedestrian_loop"])
def test_traffic_with_randomization_is_seeded_and_restores_exactly(build, task):
    """With movers and ``randomize=default``: the same seed gives the same draws, traffic and
    images; a snapshot restored into another env steps on identically, through a reset; and
    each simulation draws a variation of its own."""
    a, b = build(DEFAULT, seed=5, task=task), build(DEFAULT, seed=5, task=task)
    first, second = a.reset(), b.reset()
    assert [t.episode.variation for t in a.tasks] == [t.episode.variation for t in b.tasks]
    assert [t.episode.traffic for t in a.tasks] == [t.episode.traffic for t in b.tasks]
    assert torch.equal(first["pixels"], second["pixels"])
    variations = [t.episode.variation for t in a.tasks]
    assert None not in variations and variations[0] != variations[1]
    generator = torch.Generator().manual_seed(3)
    _, carried = drive(a, random_actions(a, 20, generator), first)
    snapshot = a.sim_state()
    tail = random_actions(a, 25, generator)
    expected, _ = drive(a, tail, carried.clone())
    assert expected["next", "done"].any(), "a reset happens after the snapshot"
    traffic = [t.episode.traffic for t in a.tasks]
    restored = build(DEFAULT, seed=99, task=task)
    restored.reset()
    restored.load_sim_state(snapshot)
    got, _ = drive(restored, tail, carried.clone())
    assert_identical(got, expected, "pixels")
    assert [t.episode.traffic for t in restored.tasks] == traffic


def test_off_is_bit_identical_to_before(build):
    """Frames and poses recorded with the code before randomisation existed."""
    reference = json.loads((DATA / "unrandomized_small_loop.json").read_text())
    env = build(seed=3)
    generator = torch.Generator().manual_seed(5)
    td = env.reset()
    frames = [hashlib.sha256(td["pixels"].numpy().tobytes()).hexdigest()]
    poses = []
    for _ in range(40):
        td["action"] = torch.randint(0, 3, (2,), generator=generator)
        step, td = env.step_and_maybe_reset(td)
        frames.append(hashlib.sha256(step["next", "pixels"].numpy().tobytes()).hexdigest())
        poses.append([list(p.pose()) for p in env.physics])
    assert frames == reference["frames"]
    assert poses == reference["poses"]


def frame_hash(frames: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(frames).tobytes()).hexdigest()


def randomized_frame_hashes() -> dict[str, list[str]]:
    """Hashes of the frames, with ``randomize=default``, of a batched env (resets, and a
    snapshot restored into another env half-way) and of ``crllk.load`` (resets included)."""
    env = make_env("small_loop", num_envs=3, seed=3, overrides=DEFAULT)
    actions = random_actions(env, 60, torch.Generator().manual_seed(5))
    tensordict = env.reset()
    batched = [frame_hash(tensordict["pixels"].numpy())]
    first, carried = drive(env, actions[:25], tensordict)
    restored = make_env("small_loop", num_envs=3, seed=99, overrides=DEFAULT)
    restored.reset()
    restored.load_sim_state(env.sim_state())
    second, _ = drive(restored, actions[25:], carried)
    for part in (first, second):
        frames = part["next", "pixels"].numpy()
        batched += [frame_hash(frames[:, t]) for t in range(frames.shape[1])]
    env.close()
    restored.close()
    single_env = load("small_loop", seed=sub_env_seeds(3, 3)[1], overrides=DEFAULT)
    single = [frame_hash(single_env.reset().observation["pixels"])]
    for step in range(45):
        timestep = single_env.step(step % 3)
        single.append(frame_hash(timestep.observation["pixels"]))
        if timestep.last():
            single.append(frame_hash(single_env.reset().observation["pixels"]))
    single_env.physics.free_renderers()
    return {"batched": batched, "single": single}


def test_randomized_frames_are_the_recorded_ones():
    """Frames recorded with the per-frame camera effects the vectorised ones replaced."""
    reference = json.loads((DATA / "randomized_small_loop.json").read_text())
    assert randomized_frame_hashes() == reference


def test_camera_effects():
    image = np.linspace(0, 255, 30 * 40 * 3).reshape(30, 40, 3).astype(np.uint8)
    assert np.abs(compress(image, 95).astype(int) - image).mean() < 2
    assert np.abs(compress(image, 50).astype(int) - image).mean() > \
        np.abs(compress(image, 95).astype(int) - image).mean()
    noisy = add_noise(image, 3.0, seed=1, frame=2)
    assert np.array_equal(noisy, add_noise(image, 3.0, seed=1, frame=2))
    assert not np.array_equal(noisy, add_noise(image, 3.0, seed=1, frame=3))
    assert 2.0 < np.std(noisy.astype(int) - image) < 4.0


@pytest.mark.parametrize(("value", "field", "problem"), [
    ("wild", "randomize", "unknown preset"),
    ({"preset": "wild"}, "randomize.preset", "unknown preset"),
    ({"camera_tilt": [0, 1]}, "randomize.camera_tilt", "unknown setting"),
    ({"camera_pitch": [1.2, 0.8]}, "randomize.camera_pitch", "above high"),
    ({"sensor_noise": [-1, 2]}, "randomize.sensor_noise", "must be >= 0"),
    ({"trim": -0.1}, "randomize.trim", "must be >= 0"),
    ({"jpeg_quality": [10, 120]}, "randomize.jpeg_quality", "must be <= 100"),
    ({"max_speed": [0, 1]}, "randomize.max_speed", "multiplier must be > 0"),
    ({"floor_color": 1.1}, "randomize.floor_color", "expected [low, high]"),
    ({"distractors": -1}, "randomize.distractors", "whole number >= 0"),
    ({"distractors": 2.5}, "randomize.distractors", "whole number >= 0"),
    ({"distractors": True}, "randomize.distractors", "whole number >= 0"),
    (3, "randomize", "expected none"),
])
def test_bad_randomize_is_one_line_naming_file_and_field(tmp_path, value, field, problem):
    path = tmp_path / "task.yaml"
    path.write_text("map:\n  tile_size: 0.585\n  tiles:\n"
                    "    - [curve_left/W, straight/W, curve_left/N]\n"
                    "    - [straight/S, asphalt, straight/N]\n"
                    "    - [curve_left/S, straight/E, curve_left/E]\n"
                    f"randomize: {json.dumps(value)}\n")
    with pytest.raises(ConfigError) as error:
        load_task_config(path)
    message = str(error.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: {field}: ")
    assert problem in message


def test_none_and_null_are_off():
    for value in ("none", None, {"camera_pitch": None}):
        assert load_task_config("small_loop", {"randomize": value}).randomize is None


def reference_compress(image: np.ndarray, quality: int) -> np.ndarray:
    """:func:`compress` one frame at a time, written out plainly: padding, RGB to YCbCr, the
    8x8 DCT along x then y, quantisation and back, each a 2-D product as the library's."""
    height, width, _ = image.shape
    padded = np.pad(image, ((0, -height % 8), (0, -width % 8), (0, 0)), mode="edge")
    rows, cols = padded.shape[0] // 8, padded.shape[1] // 8
    to_ycc = np.array([[0.299, 0.587, 0.114], [-0.168736, -0.331264, 0.5],
                       [0.5, -0.418688, -0.081312]])
    k, n = np.arange(8)[:, None], np.arange(8)[None, :]
    dct = np.cos(math.pi * (2 * n + 1) * k / 16) * math.sqrt(2 / 8)
    dct[0] /= math.sqrt(2)
    dct = dct.astype(np.float32)

    def product(array, matrix):
        return (array.reshape(-1, array.shape[-1]) @ matrix).reshape(*array.shape[:-1], -1)

    ycc = product(padded.astype(np.float32) - np.float32(128), to_ycc.T.astype(np.float32))
    blocks = ycc.reshape(rows, 8, cols, 8, 3).transpose(0, 2, 4, 1, 3)  # [.., y, x]
    coefficients = product(product(blocks, dct.T).swapaxes(-1, -2), dct.T)  # [.., u, v]
    steps = quantisation_steps(quality)
    coefficients = np.round(coefficients / steps) * steps
    blocks = product(product(coefficients, dct).swapaxes(-1, -2), dct)  # [.., y, x]
    ycc = blocks.transpose(0, 3, 1, 4, 2).reshape(rows * 8, cols * 8, 3)[:height, :width]
    rgb = product(ycc, np.linalg.inv(to_ycc).astype(np.float32).T) + np.float32(128.5)
    return np.clip(rgb, 0, 255).astype(np.uint8)


def reference_noise(image: np.ndarray, std: float, seed: int, frame: int) -> np.ndarray:
    """:func:`add_noise` written out plainly: a bank frame rotated by the key."""
    key = (seed * 0x9E3779B1 + frame * 0x85EBCA6B) & 0xFFFFFFFF
    row = noise_bank(image.size)[key % 64]
    noise = np.roll(row, -((key >> 8) % image.size)) * np.float32(std)
    return np.clip(noise + image.reshape(-1) + np.float32(0.5), 0, 255).astype(np.uint8) \
        .reshape(image.shape)


@pytest.mark.parametrize(("count", "height", "width"), [(1, 30, 40), (9, 30, 40), (17, 30, 40),
                                                        (5, 13, 21), (3, 64, 48)])
def test_batched_camera_effects_are_each_frame_s_own(count, height, width):
    """Frames compressed and noised together (over several chunks, each at its own quality
    and key) are bit for bit what each frame gets alone, from the plain reference."""
    rng = np.random.default_rng(count)
    smooth = np.linspace(0, 255, height * width * 3).reshape(height, width, 3)
    images = np.clip(smooth + rng.normal(0, 40, (count, height, width, 3)), 0, 255) \
        .astype(np.uint8)
    images[0] = rng.integers(0, 256, (height, width, 3))
    qualities = rng.integers(1, 101, count).tolist()
    stds = rng.uniform(0.0, 6.0, count).tolist()
    seeds, frames = rng.integers(0, 2**31, count).tolist(), rng.integers(0, 600, count).tolist()
    compressed = compress_frames(images, qualities)
    noisy = add_noise_frames(images, stds, seeds, frames)
    effects = [None if k % 4 == 3 else FrameEffects(qualities[k] * (k % 4 != 1),
                                                    stds[k] * (k % 4 != 2), seeds[k], frames[k])
               for k in range(count)]
    both = apply_effects(images, effects)
    for k, image in enumerate(images):
        assert np.array_equal(compressed[k], reference_compress(image, qualities[k]))
        assert np.array_equal(noisy[k], reference_noise(image, stds[k], seeds[k], frames[k]))
        expected = image
        if effects[k] is not None and effects[k].quality:
            expected = compress(expected, effects[k].quality)
        if effects[k] is not None and effects[k].noise_std > 0:
            expected = add_noise(expected, stds[k], seeds[k], frames[k])
        assert np.array_equal(both[k], expected)


def assert_frames_are_per_frame_effects(env: BatchedLaneKeepingEnv, pixels: torch.Tensor) -> None:
    """Each simulation's observed frame is its camera image now with its episode's effects
    applied to it alone (per-frame :func:`compress` and :func:`add_noise`)."""
    for k, (physics, task) in enumerate(zip(env.physics, env.tasks, strict=True)):
        variation = task.variation
        expected = compress(task.camera_image(physics), variation.jpeg_quality)
        if variation.noise_std > 0:
            expected = add_noise(expected, variation.noise_std, variation.noise_seed,
                                 task.episode.steps)
        assert np.array_equal(pixels[k].numpy(), expected), (k, task.episode.steps)


def drive_checking_effects(env: BatchedLaneKeepingEnv, actions: torch.Tensor,
                           tensordict: TensorDictBase) -> tuple[TensorDictBase, int]:
    """Step through ``actions`` with automatic resets, checking every frame observed with
    :func:`assert_frames_are_per_frame_effects`: the tensordict to carry on from and the number
    of episodes that ended."""
    ended = 0
    for action in actions:
        tensordict["action"] = action
        step, tensordict = env.step_and_maybe_reset(tensordict)
        ended += int(step["next", "done"].sum())
        assert_frames_are_per_frame_effects(env, tensordict["pixels"])
    return tensordict, ended


def test_batched_frames_are_per_frame_effects_across_resets_and_restores(build):
    """The batched env's randomised frames (effects applied to all simulations at once) match
    per-frame effects on each simulation's render, through resets and a restored snapshot."""
    env = build(DEFAULT, num_envs=4, seed=2)
    actions = random_actions(env, 50, torch.Generator().manual_seed(4))
    tensordict = env.reset()
    assert_frames_are_per_frame_effects(env, tensordict["pixels"])
    tensordict, _ = drive_checking_effects(env, actions[:20], tensordict)
    restored = build(DEFAULT, num_envs=4, seed=98)
    restored.reset()
    restored.load_sim_state(env.sim_state())
    _, ended = drive_checking_effects(restored, actions[20:], tensordict)
    assert ended >= 4, "every episode ends (horizon 30) after the snapshot"


# ----- distractors ----------------------------------------------------------------------------
DISTRACTED = {"randomize": {"preset": "default", "distractors": 40}, "horizon": 30}


def test_offroad_cells_are_the_cells_beside_the_road():
    dmap = load_task_config("small_loop").map
    cells = dmap.offroad_cells()
    half = dmap.tile_size / 2
    assert len(cells) == 5 * 5 - len(dmap.road_tiles)  # 3x3 map and a ring of one cell
    assert not any(dmap.is_road(x + half, y + half) for x, y in cells)
    assert (dmap.tile_size, dmap.tile_size) in cells  # the centre tile


def test_distractors_are_drawn_last_in_off_road_cells():
    config = PRESETS["default"]
    with_patches = dataclasses.replace(config, distractors=6)
    dmap = load_task_config("small_loop").map
    cells, size = dmap.offroad_cells(), dmap.tile_size
    plain = [draw_variation(config, MotorConfig(), 3, np.random.RandomState(k))
             for k in range(50)]
    drawn = [draw_variation(with_patches, MotorConfig(), 3, np.random.RandomState(k), cells,
                            size) for k in range(50)]
    for before, after in zip(plain, drawn, strict=True):
        assert dataclasses.replace(after, distractors=()) == before  # the other draws unchanged
        assert len(after.distractors) == 6
        for x, y, _, half_length, half_width, *rgb in after.distractors:
            assert any(x0 <= x <= x0 + size and y0 <= y <= y0 + size for x0, y0 in cells)
            low, high = DISTRACTOR_HALF_SIDES
            assert low <= half_length <= high and low <= half_width <= high
            assert all(0.0 <= c <= 1.0 for c in rgb)
        assert SceneVariation.from_dict(after.as_dict()) == after


def test_a_distractor_in_view_shows_and_each_shared_model_user_sees_its_own():
    dmap = load_task_config("small_loop").map
    first = Physics.from_map(dmap, distractors=1)
    second = first.copy(share_model=True)
    second._renderers = first._renderers
    x, y, yaw = 0.29, 0.8, math.pi / 2  # west lane of the loop, facing north
    for physics in (first, second):
        physics.set_pose(x, y, yaw)
        physics.forward()
    red = ((x, y + 0.3, 0.0, 0.06, 0.06, 1.0, 0.0, 0.0),)  # on the road, straight ahead
    first.set_variation(SceneVariation(distractors=red))
    second.set_variation(SceneVariation())

    def redness(physics):
        image = physics.render_camera(30, 40, 2).astype(int)
        return int(((image[..., 0] - image[..., 1:].max(-1)) > 80).sum())

    shown, hidden = redness(first), redness(second)
    assert shown > 10 and hidden == 0
    assert redness(first) == shown  # after the other simulation rewrote the shared model


def test_distractors_change_frames_only_and_restore_exactly(build):
    plain, distracted = build(DEFAULT, seed=4), build(DISTRACTED, seed=4)
    generator = torch.Generator().manual_seed(2)
    actions = random_actions(plain, 20, generator)
    expected, _ = drive(plain, actions, plain.reset())
    got, carried = drive(distracted, actions, distracted.reset())
    assert not torch.equal(got["next", "pixels"], expected["next", "pixels"])
    done = torch.cat([got["next", "done"], expected["next", "done"]]).reshape(-1, 20).any(0)
    first_done = int(done.nonzero()[0]) if done.any() else 20
    assert torch.equal(got["next", "reward"][:, :first_done],
                       expected["next", "reward"][:, :first_done])  # patches touch nothing
    snapshot = distracted.sim_state()
    tail = random_actions(distracted, 25, generator)
    following, _ = drive(distracted, tail, carried.clone())
    restored = build(DISTRACTED, seed=99)
    restored.reset()
    restored.load_sim_state(snapshot)
    again, _ = drive(restored, tail, carried.clone())
    assert_identical(again, following, "pixels")
