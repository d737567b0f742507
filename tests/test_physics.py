"""The Duckiebot's physics: DB18 motor model, delay, time constants, stability, divergence, actions.

Everything runs real MuJoCo. The physics floor is an infinite plane, so the robot is driven on open
ground far from the map where no road check is involved.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

import crllk
from crllk.maps import load_map
from crllk.sim.physics import Physics
from crllk.tasks.actions import (
    DISCRETE_DUTIES,
    MAX_DUTY_DIFFERENCE,
    MAX_MEAN_DUTY,
    MIN_MEAN_DUTY,
    action_duty,
)
from crllk.tasks.config import MotorConfig

CONTROL_DT = 1.0 / 30.0
SUBSTEPS = 8
"""Physics steps per 1/30 s control step."""
OPEN_GROUND = (10.0, 10.0, 0.0)
"""A pose far off the map on the infinite physics floor (m, m, rad)."""
SETTLE_STEPS = 48
"""Physics steps (0.2 s) at zero command to let the wheels settle on the floor first."""


@pytest.fixture(scope="module")
def small_loop():
    return load_map("small_loop")


@pytest.fixture(scope="module")
def physics_for(small_loop):
    """Build (and cache) a Physics per MotorConfig."""
    cache: dict[MotorConfig, Physics] = {}

    def make(motor: MotorConfig | None = None) -> Physics:
        motor = motor or MotorConfig()
        if motor not in cache:
            cache[motor] = Physics.from_map(small_loop, motor)
        physics = cache[motor]
        physics.reset()
        physics.set_pose(*OPEN_GROUND)
        physics.forward()
        physics.step(SETTLE_STEPS)
        return physics

    yield make
    for physics in cache.values():
        physics.free_renderers()


def step_response(physics: Physics, duty, seconds: float, accessor) -> tuple[np.ndarray, ...]:
    """Command ``duty`` and record ``accessor(physics)`` every physics step; time from command."""
    t0 = physics.data.time
    physics.set_wheel_duty(np.asarray(duty, dtype=float))
    times, values = [], []
    for _ in range(round(seconds / physics.model.opt.timestep)):
        physics.step(1)
        times.append(physics.data.time - t0)
        values.append(accessor(physics))
    return np.array(times), np.array(values)


def settle(physics: Physics, duty, seconds: float = 3.0) -> tuple[float, float]:
    """Forward speed (m/s) and yaw rate (rad/s) after holding ``duty`` for ``seconds``."""
    physics.set_wheel_duty(np.asarray(duty, dtype=float))
    for _ in range(round(seconds / CONTROL_DT)):
        physics.step(SUBSTEPS)
    return physics.forward_speed(), physics.yaw_rate()


def onset_time(times: np.ndarray, values: np.ndarray, threshold: float) -> float:
    """First time (s) at which |value| exceeds ``threshold``."""
    above = np.abs(values) > threshold
    assert above.any(), "the response never started"
    return float(times[np.argmax(above)])


def rise_time_63(times: np.ndarray, values: np.ndarray, delay: float) -> float:
    """Time (s) after the delay to reach 63.2 % of the final value (linearly interpolated)."""
    target = (1.0 - math.exp(-1.0)) * values[-1]
    i = int(np.argmax(values >= target))
    assert i > 0
    t = np.interp(target, values[i - 1:i + 1], times[i - 1:i + 1])
    return float(t - delay)


# ----- steady state --------------------------------------------------------------------------

def test_simulation_runs_eight_substeps_per_control_step(physics_for):
    """The physics timestep is 1/240 s, so 8 substeps make one 30 Hz control step."""
    physics = physics_for()
    assert physics.model.opt.timestep * SUBSTEPS == pytest.approx(CONTROL_DT)


@pytest.mark.parametrize(("duty", "speed", "yaw_rate"), [
    ((0.3, 0.3), 0.18, 0.0),       # discrete "straight"
    ((0.04, 0.4), 0.132, 1.35),    # discrete "left"
    ((0.4, 0.04), 0.132, -1.35),   # discrete "right"
    ((1.0, 1.0), 0.6, 0.0),        # full duty: the DB18 top speed
    ((-0.5, -0.5), -0.3, 0.0),     # reverse
    ((-0.4, 0.4), 0.0, 3.0),       # spin on the spot
])
def test_duty_settles_at_db18_steady_state(physics_for, duty, speed, yaw_rate):
    """Held duties settle at v = 0.6 mean(d) m/s and w = 3.75 (d_r - d_l) rad/s, within 10 %."""
    v, w = settle(physics_for(), duty)
    assert v == pytest.approx(speed, rel=0.10, abs=0.005)
    assert w == pytest.approx(yaw_rate, rel=0.10, abs=0.02)


def test_steady_state_holds_while_driving(physics_for):
    """Once settled, speed stays constant over a further second of driving (no drift or decay)."""
    physics = physics_for()
    v1, w1 = settle(physics, (0.04, 0.4))
    v2, w2 = settle(physics, (0.04, 0.4), seconds=1.0)
    assert v2 == pytest.approx(v1, rel=0.01)
    assert w2 == pytest.approx(w1, rel=0.01)


def test_wheels_roll_without_slipping(physics_for):
    """At steady speed the mean wheel rate times the wheel radius equals the forward speed."""
    physics = physics_for()
    v, _ = settle(physics, (0.5, 0.5))
    assert physics.wheel_speeds().mean() * 0.0318 == pytest.approx(v, rel=0.03)


def test_copy_keeps_the_motor_settings(physics_for):
    """A copied Physics keeps its motor config and drives exactly like the original."""
    physics = physics_for(MotorConfig(max_speed=0.3))
    twin = physics.copy()
    assert twin.motor == physics.motor
    for p in (physics, twin):
        p.set_wheel_duty(np.array([1.0, 1.0]))
        p.step(3 * 240)
    assert twin.forward_speed() == pytest.approx(physics.forward_speed(), rel=1e-6)
    assert physics.forward_speed() == pytest.approx(0.3, rel=0.05)


# ----- delay ---------------------------------------------------------------------------------

@pytest.mark.parametrize("delay", [0.15, 0.05])
def test_command_delay_as_configured(physics_for, delay):
    """From rest the robot does not move before the delay and clearly moves just after it."""
    physics = physics_for(MotorConfig(delay=delay))
    times, speed = step_response(physics, (0.3, 0.3), delay + 0.2, Physics.forward_speed)
    assert np.abs(speed[times < delay - 1e-9]).max() < 1e-3
    onset = onset_time(times, speed, threshold=5e-3)
    assert delay <= onset <= delay + 0.05
    assert speed[times <= delay + 4 * CONTROL_DT][-1] > 0.03  # within four control steps


def test_delay_shifts_the_onset(physics_for):
    """A 0.1 s longer delay moves the onset of motion 0.1 s later (to one physics step)."""
    onsets = []
    for delay in (0.05, 0.15):
        physics = physics_for(MotorConfig(delay=delay))
        times, speed = step_response(physics, (0.3, 0.3), 0.3, Physics.forward_speed)
        onsets.append(onset_time(times, speed, threshold=5e-3))
    assert onsets[1] - onsets[0] == pytest.approx(0.1, abs=1.5 / 240)


def test_turn_command_is_delayed_too(physics_for):
    """The yaw rate also stays at zero until the delay has passed."""
    physics = physics_for(MotorConfig(delay=0.15))
    times, yaw_rate = step_response(physics, (0.04, 0.4), 0.35, Physics.yaw_rate)
    assert np.abs(yaw_rate[times < 0.15 - 1e-9]).max() < 1e-3
    assert 0.15 <= onset_time(times, yaw_rate, threshold=1e-2) <= 0.2


# ----- time constants ------------------------------------------------------------------------

@pytest.mark.parametrize("motor", [MotorConfig(), MotorConfig(linear_time_constant=0.4)],
                         ids=["tau0.2", "tau0.4"])
def test_forward_time_constant(physics_for, motor):
    """The forward speed reaches 63.2 % of its final value one time constant after the delay."""
    physics = physics_for(motor)
    times, speed = step_response(physics, (0.3, 0.3), motor.delay + 8 * motor.linear_time_constant,
                                 Physics.forward_speed)
    assert rise_time_63(times, speed, motor.delay) == pytest.approx(
        motor.linear_time_constant, rel=0.15)


@pytest.mark.parametrize("motor", [MotorConfig(), MotorConfig(yaw_time_constant=0.5)],
                         ids=["tau0.25", "tau0.5"])
def test_yaw_time_constant(physics_for, motor):
    """The yaw rate reaches 63.2 % of its final value one time constant after the delay."""
    physics = physics_for(motor)
    times, yaw_rate = step_response(physics, (-0.4, 0.4), motor.delay + 8 * motor.yaw_time_constant,
                                    Physics.yaw_rate)
    assert rise_time_63(times, yaw_rate, motor.delay) == pytest.approx(
        motor.yaw_time_constant, rel=0.15)


def test_response_is_first_order_without_overshoot(physics_for):
    """The speed rises monotonically to its final value (a first-order lag, not an oscillator)."""
    physics = physics_for()
    _, speed = step_response(physics, (1.0, 1.0), 2.0, Physics.forward_speed)
    assert speed.max() <= speed[-1] * 1.01
    assert np.all(np.diff(speed[speed > 0.01]) > -1e-4)


# ----- stability -----------------------------------------------------------------------------

def run_bang_bang(physics: Physics, steps: int, seed: int) -> None:
    """Random bang-bang duties (each wheel -1 or +1, new every control step); checks the end."""
    instabilities = physics.instabilities
    rng = np.random.default_rng(seed)
    duties = rng.choice([-1.0, 1.0], size=(steps, 2))
    for duty in duties:
        physics.set_wheel_duty(duty)
        physics.step(SUBSTEPS)
        assert not physics.diverged
    assert physics.instabilities == instabilities
    assert np.all(np.isfinite(physics.data.qpos))
    assert np.all(np.isfinite(physics.data.qvel))
    # The robot stays upright on its wheels: axle at wheel height, quaternion x, y ~ 0.
    assert physics.data.qpos[2] == pytest.approx(0.0318, abs=0.005)
    assert np.abs(physics.data.qpos[4:6]).max() < 0.05
    assert abs(physics.forward_speed()) <= 0.61
    assert abs(physics.yaw_rate()) <= 7.6


def test_bang_bang_duties_stay_stable(physics_for):
    """5,000 control steps of random full-duty commands raise nothing and stay finite."""
    physics = physics_for()
    run_bang_bang(physics, 5_000, seed=0)


@pytest.mark.slow
def test_bang_bang_duties_stay_stable_long(physics_for):
    """100,000 control steps of random full-duty commands raise nothing and stay finite."""
    physics = physics_for()
    run_bang_bang(physics, 100_000, seed=1)


# ----- divergence ----------------------------------------------------------------------------

def _huge_velocity(physics: Physics) -> None:
    physics.data.qvel[:] = 1e10


def _nan_position(physics: Physics) -> None:
    physics.data.qpos[0] = np.nan


def _huge_force(physics: Physics) -> None:
    physics.data.qfrc_applied[:] = 1e30


@pytest.mark.parametrize("corrupt", [_huge_velocity, _nan_position, _huge_force],
                         ids=["huge_qvel", "nan_qpos", "huge_force"])
def test_divergence_is_caught_and_counted(physics_for, corrupt):
    """A divergence inside Physics.step does not raise: it is flagged, counted and reset."""
    physics = physics_for()
    before = physics.instabilities
    corrupt(physics)
    physics.step(SUBSTEPS)
    assert physics.diverged
    assert physics.instabilities == before + 1
    assert np.all(np.isfinite(physics.data.qpos))
    assert np.all(np.isfinite(physics.data.qvel))
    assert np.all(physics.data.qfrc_applied == 0.0)
    # The next step is a normal one again.
    physics.set_pose(*OPEN_GROUND)
    physics.step(SUBSTEPS)
    assert not physics.diverged
    assert physics.instabilities == before + 1


def test_divergence_ends_the_episode_as_unstable():
    """Through crllk.load a divergence ends the episode with discount 0 and 'unstable'."""
    env = crllk.load("small_loop", observation="state", action="discrete", seed=3)
    env.reset()
    for _ in range(5):
        assert env.step(2).mid()
    env.physics.data.qvel[:] = 1e10
    ts = env.step(2)
    assert ts.last()
    assert ts.discount == 0.0
    assert env.task.outcome.termination == "unstable"
    assert ts.reward == 0.0
    assert env.physics.instabilities == 1
    assert np.all(np.isfinite(ts.observation["state"]))
    assert np.isfinite(ts.observation["cost_lane"])
    assert np.all(np.isfinite(env.physics.data.qpos))
    # The run goes on: the next step starts a fresh episode on the road.
    ts = env.step(2)
    assert ts.first()
    assert env.task.map.is_road(*env.physics.pose()[:2])
    assert env.step(2).mid()


# ----- actions -------------------------------------------------------------------------------

def test_velocity_to_duty_inverse_kinematics():
    """u = v / (R k) = 0.5 / (0.0318 * 27) on both wheels when steering is 0."""
    duty = action_duty("duckietown", (0.5, 0.0))
    np.testing.assert_allclose(duty, [0.5 / (0.0318 * 27)] * 2, rtol=1e-9)
    np.testing.assert_allclose(duty, [0.5824, 0.5824], atol=1e-4)


def test_steering_splits_the_wheels():
    """Steering a adds +-a b / 2 / (R k) to the right / left duty."""
    left, right = action_duty("duckietown", (0.3, 0.5))
    delta = 0.5 * 0.5 * 0.102 / (0.0318 * 27)
    assert right == pytest.approx(0.3 / (0.0318 * 27) + delta)
    assert left == pytest.approx(0.3 / (0.0318 * 27) - delta)


@pytest.mark.parametrize(("action", "expected"), [
    ((1.0, 0.0), (1.0, 1.0)),
    ((-1.0, 0.0), (-1.0, -1.0)),
    ((0.86, 0.0), (1.0, 1.0)),
    ((5.0, -3.0), (1.0, 1.0)),
    ((0.0, 1.0), (-0.0594, 0.0594)),
])
def test_velocity_to_duty_saturates(action, expected):
    """Duties are clipped to [-1, 1] (and inputs to the action box first)."""
    duty = action_duty("duckietown", action)
    np.testing.assert_allclose(duty, expected, atol=1e-4)
    assert np.all(np.abs(duty) <= 1.0)


def test_positive_steering_turns_left(physics_for):
    """Positive steering drives the right wheel faster, and the robot yaws counter-clockwise."""
    duty = action_duty("duckietown", (0.2, 1.0))
    assert duty[1] > duty[0]
    physics = physics_for()
    _, yaw_rate = settle(physics, duty, seconds=1.0)
    assert yaw_rate > 0.1
    _, yaw_rate = settle(physics, action_duty("duckietown", (0.2, -1.0)), seconds=1.0)
    assert yaw_rate < -0.1


@pytest.mark.parametrize(("action", "expected"), [
    ((0.0, 0.0), (0.35, 0.35)),        # mean 0.1 + 0.5 * 0.5 = 0.35
    ((-1.0, 0.0), (0.1, 0.1)),         # the slowest drive still moves forward
    ((1.0, 0.0), (0.6, 0.6)),
    ((0.0, 1.0), (0.1, 0.6)),          # difference 0.5: right wheel faster, turns left
    ((0.0, -0.4), (0.45, 0.25)),
    ((5.0, -3.0), (0.85, 0.35)),       # inputs clipped to the box first
])
def test_continuous_drive_and_turn(action, expected):
    """velocity sets the mean duty in [0.1, 0.6]; steering the difference up to 0.5."""
    assert (MIN_MEAN_DUTY, MAX_MEAN_DUTY, MAX_DUTY_DIFFERENCE) == (0.1, 0.6, 0.5)
    np.testing.assert_allclose(action_duty("continuous", action), expected, atol=1e-12)


def test_continuous_cannot_stand_still_by_dithering(physics_for):
    """Alternating velocity +1 and -1 every step still drives forward (the mean duty of both
    is positive), unlike the Duckietown mapping, where it stands still."""
    for action_type, moves in (("continuous", True), ("duckietown", False)):
        physics = physics_for()
        x0, y0, _ = physics.pose()
        for k in range(60):
            physics.set_wheel_duty(action_duty(action_type, (1.0 if k % 2 else -1.0, 0.0)))
            physics.step(SUBSTEPS)
        x, y, _ = physics.pose()
        assert (math.hypot(x - x0, y - y0) > 0.2) == moves, action_type


def test_continuous_reaches_the_discrete_turn_rates(physics_for):
    """Full steering yaws faster than a discrete turn (1.35 rad/s) at any velocity; the
    Duckietown mapping stays below 0.5 rad/s."""
    physics = physics_for()
    _, discrete_rate = settle(physics, action_duty("discrete", 0), seconds=1.5)
    for velocity in (-1.0, 0.0, 1.0):
        _, rate = settle(physics_for(), action_duty("continuous", (velocity, 1.0)), seconds=1.5)
        assert rate > discrete_rate > 1.2, velocity
    _, rate = settle(physics_for(), action_duty("duckietown", (0.2, 1.0)), seconds=1.5)
    assert 0.1 < rate < 0.5


def test_discrete_action_table():
    """0 turns left (0.04, 0.4), 1 turns right (0.4, 0.04), 2 goes straight (0.3, 0.3)."""
    np.testing.assert_array_equal(action_duty("discrete", 0), [0.04, 0.4])
    np.testing.assert_array_equal(action_duty("discrete", 1), [0.4, 0.04])
    np.testing.assert_array_equal(action_duty("discrete", np.int64(2)), [0.3, 0.3])


def test_discrete_duty_cannot_change_the_action_table():
    """A returned duty is an immutable pair, equal to the table's row."""
    duty = action_duty("discrete", 2)
    assert isinstance(duty, tuple)
    np.testing.assert_array_equal(DISCRETE_DUTIES[2], duty)


@pytest.mark.parametrize("action", [-1, 3, 10])
def test_discrete_action_out_of_range(action):
    """Actions other than 0, 1, 2 raise a ValueError naming the action."""
    with pytest.raises(ValueError, match=str(action)):
        action_duty("discrete", action)


def test_freeing_an_older_simulation_leaves_the_camera_of_a_newer_one_intact():
    """A garbage-collected environment's renderers are closed in their own GL context: closed
    in the current one (another renderer's), they freed that renderer's textures and its later
    images were garbage (a mean error of about 100 of 255)."""
    import gc

    import crllk

    older = [crllk.load(task, observation="pixels", seed=3) for task in ("zigzag", "small_loop")]
    for index in range(len(older)):
        older[index].reset()
    newer = crllk.load("zigzag", observation="pixels", seed=3)
    step = newer.reset()
    for _ in range(3):
        step = newer.step(2)
    while older:
        del older[0]
        gc.collect()
        again = newer.physics.render_camera(30, 40, 2)
        np.testing.assert_array_equal(again, step.observation["pixels"])


@pytest.mark.parametrize(("given", "expected"), [(None, "0"), ("3", "3")])
def test_llvmpipe_draws_on_the_calling_thread_unless_the_user_says_otherwise(given, expected):
    """``import crllk`` sets LP_NUM_THREADS=0 (Mesa's rasteriser without helper threads, read
    when the first GL context is made) and keeps a value the user set."""
    env = {k: v for k, v in os.environ.items() if k != "LP_NUM_THREADS"}
    if given is not None:
        env["LP_NUM_THREADS"] = given
    probe = "import os, crllk; print(os.environ['LP_NUM_THREADS'])"
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                         text=True, check=True).stdout.strip()
    assert out == expected


def test_the_mjcf_servos_have_the_documented_gains(physics_for):
    """Each velocity servo's bias is -kv and its gain kv times the ctrl-to-tendon-speed factor
    (1/R forward, b/R turning), with the constants' kv, R and b."""
    import mujoco

    from crllk.sim.constants import (
        FORWARD_ACTUATOR,
        FORWARD_SERVO_GAIN,
        TURN_ACTUATOR,
        TURN_SERVO_GAIN,
        WHEEL_DISTANCE,
        WHEEL_RADIUS,
    )

    model = physics_for().model.ptr
    for name, kv, factor in ((FORWARD_ACTUATOR, FORWARD_SERVO_GAIN, 1 / WHEEL_RADIUS),
                             (TURN_ACTUATOR, TURN_SERVO_GAIN, WHEEL_DISTANCE / WHEEL_RADIUS)):
        actuator = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        assert model.actuator_biasprm[actuator, 2] == pytest.approx(-kv)
        assert model.actuator_gainprm[actuator, 0] == pytest.approx(kv * factor, rel=1e-4)
