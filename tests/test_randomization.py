"""Per-episode domain randomisation (``randomize``): seeded draws within their ranges, visible
in the images, the camera pose and the motion, restored exactly from snapshots, and nothing
changed when it is off."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from test_env_state import assert_identical, drive, random_actions

from crllk.envs.batched import BatchedLaneKeepingEnv, make_env, sub_env_seeds
from crllk.errors import ConfigError
from crllk.sim import constants as C
from crllk.sim.camera_effects import add_noise, compress
from crllk.sim.motor import MotorConfig
from crllk.tasks.config import load_task_config
from crllk.tasks.lane_keeping import load
from crllk.tasks.randomization import PRESETS, draw_variation

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
