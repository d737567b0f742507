"""From a run to wheel commands: the ONNX export agrees with PyTorch, camera frames are prepared
as in training, and the pilot and ``crllk.deploy`` turn frames into commands."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import onnxruntime
import pytest
import torch
from PIL import Image
from tiny_runs import run_in_process
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from crllk import deploy, export
from crllk.cli import exit_status
from crllk.deployment import ros_node
from crllk.deployment.export import deployed_policy
from crllk.deployment.frames import read_frames
from crllk.deployment.pilot import Pilot
from crllk.images import box_average
from crllk.tasks.actions import action_duty
from crllk.tasks.frames import crop_to_aspect, policy_image
from crllk.training.build import build_env
from crllk.training.runs import load_actor, load_run_config, played_action

RECORDED = 1008
"""Observations per parity check: 16 simulations x 63 steps."""


HISTORY = ["obs.history=2", "obs.history_stride=3"]
"""A policy that reads its last two images, three steps apart."""


STATE_DEPENDENT_STD = ["model.state_dependent_std=true"]
"""A Gaussian policy whose spread is a head of its network."""


@pytest.fixture(scope="module", params=["pixels-discrete", "pixels-continuous", "state-discrete",
                                        "pixels-discrete-history", "state-stoppable",
                                        "state-continuous-statestd"])
def exported(request, tmp_path_factory):
    obs, action, *extras = request.param.split("-")
    run = run_in_process(tmp_path_factory.mktemp(request.param) / "run", 1,
                         [f"obs={obs}", f"action={action}", "eval.final=false",
                          *(HISTORY if "history" in extras else []),
                          *(STATE_DEPENDENT_STD if "statestd" in extras else [])])
    assert exit_status(lambda: export.main([f"run={run}"])) == 0
    return run, obs, action


def _recorded_observations(run, count: int = RECORDED):
    """Observations of the run's task from a rollout of its own deployed policy, with the
    actions it plays in evaluation (a discrete run's expected duties, in a duty env), and the
    action type they are in."""
    config = load_run_config(run)
    env = build_env(config, num_envs=16, seed=7, action=played_action(config, True))
    actor, _ = load_actor(run, env, deployed=True)
    observations, actions = [], []
    td = env.reset()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        while len(observations) < count:
            td = actor(td)
            observations += list(td[config.obs.name].unbind(0))
            actions += list(td["action"].unbind(0))
            td = step_mdp(env.step(td))
    env.close()
    return observations, actions, env.action_type


def test_onnx_actions_equal_pytorch_on_recorded_observations(exported):
    run, _, _ = exported
    policy, _ = deployed_policy(run)
    session = onnxruntime.InferenceSession(str(run / "policy.onnx"))
    observations, actor_actions, action = _recorded_observations(run)
    assert len(observations) >= 1000
    with torch.no_grad():
        torch_duty = np.stack([policy(o).numpy() for o in observations])
    onnx_duty = np.stack([session.run(None, {"observation": o.numpy()})[0]
                          for o in observations])
    actor_duty = np.array([action_duty(action, a.numpy()) for a in actor_actions])
    assert np.abs(onnx_duty - torch_duty).max() <= 1e-5
    # the exported network is the policy the evaluation of the deployed policy plays
    assert np.abs(torch_duty - actor_duty).max() <= 1e-6
    assert onnx_duty.shape == (len(observations), 2)


@pytest.mark.parametrize("exported", ["pixels-discrete-history"], indirect=True)
def test_the_pilot_remembers_images_as_the_training_env_stacks_them(exported):
    """Fed the newest image of each observation of an episode, the pilot stacks exactly what
    the env showed the policy, and starts again after :meth:`Pilot.reset`."""
    run, _, _ = exported
    config = load_run_config(run)
    assert config.obs.history == 2
    pilot = Pilot.from_onnx(run / "policy.onnx")
    env = build_env(config, num_envs=1, seed=3)
    try:
        for _ in range(2):
            pilot.reset()
            td = env.reset()
            for _ in range(12):
                stacked = td["pixels"][0].numpy()
                np.testing.assert_array_equal(pilot.remember(stacked[..., :3]), stacked)
                td = step_mdp(env.rand_step(td))
    finally:
        env.close()


def test_a_640x480_frame_becomes_the_training_image():
    """An array of a whole multiple of 30x40 is box-averaged as training does; a JPEG of a
    rendered 640x480 frame lands within JPEG noise of the simulator's own 30x40 image; colours
    stay RGB; other aspect ratios are cropped about the centre."""
    import crllk

    env = crllk.load("zigzag", observation="pixels", seed=3)
    step = env.reset()
    frame = env.physics.render_camera(480, 640, 1)
    np.testing.assert_array_equal(policy_image(frame), box_average(frame, 16))
    jpeg = io.BytesIO()
    Image.fromarray(frame).save(jpeg, format="JPEG", quality=95)
    prepared = policy_image(jpeg.getvalue())
    difference = np.abs(prepared.astype(int) - step.observation["pixels"].astype(int))
    assert prepared.shape == (30, 40, 3) and difference.mean() < 4.0
    red = np.zeros((480, 640, 3), np.uint8)
    red[..., 0] = 200
    assert policy_image(red)[0, 0].tolist() == [200, 0, 0]
    wide = np.zeros((90, 160, 3), np.uint8)
    wide[:, 20:140] = 255  # the centred 4:3 part
    assert crop_to_aspect(wide, 30, 40).min() == 255
    assert policy_image(wide).shape == (30, 40, 3)


def test_the_pilot_takes_jpeg_bytes_and_arrays(exported):
    run, obs, _ = exported
    pilot = Pilot.from_onnx(run / "policy.onnx")
    if obs == "state":
        command = pilot.step(np.zeros(pilot.observation_shape, np.float32))
    else:
        frame = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
        jpeg = io.BytesIO()
        Image.fromarray(frame).save(jpeg, format="JPEG")
        command = pilot.step(jpeg.getvalue())
        # the first frame of a drive fills the whole memory of a policy with a history
        expected = pilot.duty(np.tile(policy_image(jpeg.getvalue()),
                                      (1, 1, pilot.observation_shape[2] // 3)))
        assert (command.vel_left, command.vel_right) == pytest.approx(expected.tolist())
    assert -1 <= command.vel_left <= 1 and -1 <= command.vel_right <= 1


@pytest.fixture(scope="module")
def pixel_policy(tmp_path_factory):
    run = run_in_process(tmp_path_factory.mktemp("pixel-policy") / "run", 1,
                         ["obs=pixels", "eval.final=false"])
    assert exit_status(lambda: export.main([f"run={run}"])) == 0
    return run / "policy.onnx"


def test_deploy_writes_the_commands_of_a_folder_and_of_a_video(pixel_policy, tmp_path, capsys):
    import cv2

    frames = tmp_path / "frames"
    frames.mkdir()
    rng = np.random.default_rng(1)
    images = [rng.integers(0, 256, (480, 640, 3), dtype=np.uint8) for _ in range(4)]
    for k, image in enumerate(images):
        Image.fromarray(image).save(frames / f"{k:03d}.jpg")
    out = tmp_path / "commands.csv"
    assert exit_status(lambda: deploy.main(["--policy", str(pixel_policy),
                                            "--frames", str(frames), "--out", str(out)])) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "frame,vel_left,vel_right,latency_ms" and len(lines) == 5
    assert lines[1].startswith("000.jpg,")
    assert "latency per frame" in capsys.readouterr().out
    video = tmp_path / "drive.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30, (640, 480))
    for image in images:
        writer.write(cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    writer.release()
    assert exit_status(lambda: deploy.main(["--policy", str(pixel_policy),
                                            "--frames", str(video), "--out", str(out)])) == 0
    assert len(out.read_text().splitlines()) == 5


@pytest.mark.parametrize(("command", "argv", "words"), [
    ("export", ["run={missing}"], "export: run:"),
    ("export", [], "export: run:"),
    ("deploy", ["--policy", "{missing}", "--frames", "{tmp}"], "policy: no such file"),
    ("deploy", ["--policy", "{not_onnx}", "--frames", "{tmp}"], "policy: not an ONNX model"),
    ("deploy", ["--policy", "{plain_onnx}", "--frames", "{tmp}"], "not a crllk policy"),
    ("ros_node", ["--policy", "{missing}", "--vehicle", "duck"], "policy: no such file"),
    ("ros_node", ["--policy", "{missing}", "--vehicle", "duck", "--rate", "0"],
     "--rate: must be a finite number above 0"),
    ("ros_node", ["--policy", "{missing}"], "--vehicle"),
])
def test_bad_input_is_one_line(tmp_path, capsys, command, argv, words):
    paths = {"missing": tmp_path / "missing", "tmp": tmp_path,
             "not_onnx": tmp_path / "notes.onnx", "plain_onnx": tmp_path / "plain.onnx"}
    paths["not_onnx"].write_text("not a model")
    program = torch.onnx.export(torch.nn.Linear(2, 2).eval(), (torch.zeros(2),), dynamo=True,
                                verbose=False)
    paths["plain_onnx"].write_bytes(program.model_proto.SerializeToString())
    capsys.readouterr()  # what the export above printed is not the command's
    main = {"export": export.main, "deploy": deploy.main, "ros_node": ros_node.main}[command]
    try:
        status = exit_status(lambda: main([a.format(**paths) for a in argv]))
    except SystemExit as exit_info:
        status = exit_info.code
    err = capsys.readouterr().err.strip()
    assert status == 2 and err.startswith("error: ") and words in err, err
    assert len(err.splitlines()) == 1


@pytest.mark.parametrize("key, value", [("history", "[0, 1]"), ("history", "[2]"),
                                        ("history", "[2, -3]"), ("history", "two"),
                                        ("supersample", "0"), ("supersample", "eight")])
def test_a_policy_with_bad_metadata_is_one_line(pixel_policy, key, value):
    """An exported file whose ``crllk.history`` or ``crllk.supersample`` was edited by hand: a
    ConfigError naming the file and the metadata field, not a traceback."""
    from crllk.errors import ConfigError

    pilot = Pilot.from_onnx(pixel_policy)
    metadata = {**pilot.metadata, key: value}
    with pytest.raises(ConfigError) as error:
        Pilot(pilot.session, metadata, str(pixel_policy))
    assert str(error.value).startswith(f"{pixel_policy}: crllk.{key}: ")
    assert "\n" not in str(error.value)


ROBOT_RUN = (Path(__file__).resolve().parents[1] / "results" / "runs" / "pixels" / "small_loop"
             / "CRLLK-D-rand-ss8-a0.5-seed1")
"""The committed policy trained for the robot (randomised, images supersampled 8x)."""


def test_the_robot_policy_acts_alike_on_camera_frames(tmp_path):
    """The committed robot policy, exported, gives the same command on JPEG 640x480 camera
    frames as on the simulator's own images on at least 99 of 100 frames, its images rendered
    at the supersampling of its training."""
    from crllk.deployment.parity import pilot_parity

    out = tmp_path / "robot.onnx"
    assert exit_status(lambda: export.main([f"run={ROBOT_RUN}", f"out={out}"])) == 0
    pilot = Pilot.from_onnx(out)
    assert pilot.supersample == 8
    parity = pilot_parity(pilot, "small_loop", frames=100)
    assert parity.same >= 99 and parity.mean_pixel_difference < 1.0, parity


def test_the_node_without_ros_is_one_line(pixel_policy, capsys):
    """Off the robot (no rclpy here) the node names what is missing, in one line."""
    with pytest.raises(SystemExit) as exit_info:
        ros_node.main(["--policy", str(pixel_policy), "--vehicle", "duck"])
    status = exit_info.value.code
    err = capsys.readouterr().err.strip()
    assert status == 2 and err.startswith("error: ros_node: cannot import rclpy"), err
    assert len(err.splitlines()) == 1


def test_the_robot_needs_no_training_stack():
    """The pilot and the ROS 2 node import numpy, Pillow, PyYAML and ONNX Runtime, and none of the
    simulation or training libraries a Duckiebot would otherwise have to install."""
    import subprocess
    import sys

    heavy = ["torch", "torchrl", "tensordict", "mujoco", "dm_control", "hydra", "rerun",
             "matplotlib", "cv2", "gymnasium"]
    code = ("import sys, crllk.deployment.ros_node, crllk.deploy; "
            f"print(sorted(m for m in {heavy!r} if m in sys.modules))")
    found = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True).stdout.strip()
    assert found == "[]", found


def test_frames_that_are_not_frames(tmp_path):
    from crllk.errors import ConfigError

    with pytest.raises(ConfigError, match="frame: not an image"):
        policy_image(b"not a jpeg")
    with pytest.raises(ConfigError, match=r"expected RGB uint8 of shape \(height, width, 3\)"):
        policy_image(np.zeros((480, 640), np.uint8))
    with pytest.raises(ConfigError, match="smaller than the policy's"):
        policy_image(np.zeros((12, 16, 3), np.uint8))
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ConfigError, match="frames: no images"):
        list(read_frames(empty))


def test_parity_of_camera_frames_and_simulator_images(pixel_policy, capsys):
    """``crllk.deploy --parity`` drives the follower, and compares the pilot on JPEG frames of
    640x480 with the policy on the simulator's 30x40 images, which differ by JPEG noise."""
    from crllk.deployment.parity import pilot_parity

    pilot = Pilot.from_onnx(pixel_policy)
    assert pilot.supersample == 2  # the task's, as the run trained
    parity = pilot_parity(pilot, "small_loop", frames=20)
    assert parity.frames == 20 and 0 <= parity.same <= 20
    assert 0 < parity.mean_pixel_difference < 4.0
    # a policy trained on images supersampled 8x is compared with images rendered so, which
    # lie closer to the camera's 640x480 frames
    finer = Pilot(pilot.session, {**pilot.metadata, "supersample": "8"}, pilot.source)
    assert pilot_parity(finer, "small_loop", frames=20).mean_pixel_difference < (
        parity.mean_pixel_difference / 2)
    assert exit_status(lambda: deploy.main(["--policy", str(pixel_policy), "--parity",
                                            "small_loop", "--parity-frames", "5"])) == 0
    assert "small_loop: the same command on" in capsys.readouterr().out


def test_every_policy_action_type_exports():
    """The pilot's list (kept free of imports for the robot) names every policy action type."""
    from crllk.deployment.onnx_names import EXPORTABLE_ACTIONS
    from crllk.tasks.actions import POLICY_ACTIONS

    assert EXPORTABLE_ACTIONS == POLICY_ACTIONS
