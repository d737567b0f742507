"""The real rerun viewer, run headless (software Vulkan, installed by scripts/install-egl.sh):
a recording's camera panel shows the road and no view reports an error; a camera logged the old,
broken way is caught; a training run's live view reaches the viewer from its first iteration to
its last. Marked ``viewer`` (part of the default run)."""

from __future__ import annotations

import io
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
import rerun.blueprint as rrb
from PIL import Image
from tiny_runs import TINY

import crllk
from crllk.recording import headless
from crllk.recording.entities import CAMERA, CAMERA_VIEW, IMAGE
from crllk.recording.recorder import record_episodes
from crllk.recording.viewer import free_port, viewer_listening
from crllk.tasks.follower import FollowerPolicy

pytestmark = pytest.mark.viewer

REPO = Path(__file__).resolve().parents[1]
HORIZON = 45
"""Steps of the recorded episode (1.5 s)."""
SHOT_TIME = 1.0
"""Where the camera is checked (s of sim_time)."""
MIN_STD = 12.0
"""The camera panel's centre is no flat colour: std of its pixel values (0-255) above this."""
MAX_SHARE = 0.5
"""... and no single colour covers more than this share of it."""
ITERATIONS = 3


def image(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def centre(pixels: np.ndarray) -> np.ndarray:
    """The middle half of a view in each direction (away from its borders)."""
    h, w = pixels.shape[:2]
    return pixels[h // 4:3 * h // 4, w // 4:3 * w // 4]


def flat(pixels: np.ndarray) -> bool:
    _, counts = np.unique(pixels.reshape(-1, 3), axis=0, return_counts=True)
    return pixels.std() < MIN_STD or counts.max() / counts.sum() > MAX_SHARE


@pytest.fixture(scope="module")
def viewer():
    with headless.headless_viewer() as client:
        yield client


@pytest.fixture(scope="module")
def follower_recording(tmp_path_factory) -> Path:
    """One short episode of the scripted follower on obstacle_loop from the 30x40 camera."""
    path = tmp_path_factory.mktemp("viewer") / "follower.rrd"
    env = crllk.make_env("obstacle_loop", observation="pixels", action="duty", seed=1,
                         overrides={"horizon": HORIZON})
    record_episodes(env, FollowerPolicy(env), 1, path)
    env.close()
    return path


def broken_camera_recording(path: Path, pixels: np.ndarray) -> Path:
    """The same image under a pinhole given by field of view and aspect ratio as well as its
    resolution, which rerun 0.41 turns into a resolution of [aspect, 1]."""
    rec = rr.RecordingStream("crllk-broken-camera", recording_id="broken")
    rec.save(path, default_blueprint=rrb.Blueprint(rrb.Spatial2DView(origin=CAMERA,
                                                                     name=CAMERA_VIEW)))
    rec.set_time("sim_time", duration=0.0)
    rec.log(CAMERA, rr.Pinhole(fov_y=1.0, aspect_ratio=4 / 3, width=40, height=30))
    rec.log(IMAGE, rr.Image(pixels))
    rec.disconnect()
    return path


def shoot(viewer, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The whole window and the camera panel at SHOT_TIME, the recording alone open."""
    viewer.close("all")
    viewer.open(str(path))
    headless.wait_loaded(viewer, "sim_time")
    headless.seek(viewer, "sim_time", SHOT_TIME)
    camera = headless.view_id(viewer, CAMERA_VIEW)
    return image(headless.settled_png(viewer)), image(headless.settled_png(viewer, camera))


def test_camera_panel_shows_the_road_and_no_view_fails(viewer, follower_recording):
    window, camera = shoot(viewer, follower_recording)
    assert window.shape == (headless.WINDOW_SIZE[1], headless.WINDOW_SIZE[0], 3)
    assert camera.shape[0] > 100 and camera.shape[1] > 100
    assert not flat(centre(camera)), (centre(camera).std(), "camera panel is one flat colour")
    errors = [p for p in headless.view_problems(viewer) if p.severity == "error"]
    assert not errors


def test_a_broken_camera_is_caught(viewer, tmp_path):
    road = np.zeros((30, 40, 3), np.uint8)
    road[:, :, 0] = np.arange(40) * 6  # a gradient: not flat when shown at its real size
    road[15:, :, 1] = 200
    _, camera = shoot(viewer, broken_camera_recording(tmp_path / "broken.rrd", road))
    assert flat(centre(camera))


def test_missing_timeline_and_view_are_named(viewer, follower_recording):
    viewer.close("all")
    viewer.open(str(follower_recording))
    with pytest.raises(headless.ScreenshotError, match="sim_time"):
        headless.wait_loaded(viewer, "no_such_timeline")
    with pytest.raises(headless.ScreenshotError, match=CAMERA_VIEW):
        headless.view_id(viewer, "no such view")


def test_training_streams_its_live_view_from_start_to_end(viewer, tmp_path):
    """A run with ``live=serve``: the viewer connected while it trains receives every
    iteration's series and the recordings of ``record_every``, and nothing fails to show."""
    port = free_port()
    command = [sys.executable, "-m", "crllk.train", *TINY, f"run_dir={tmp_path / 'run'}",
               f"total_frames={ITERATIONS * 16}", "record_every=2", "live=serve",
               f"live_port={port}"]
    viewer.close("all")
    training = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
    try:
        while not viewer_listening(port):
            assert training.poll() is None, training.communicate()[1][-2000:]
            time.sleep(0.2)
        viewer.open(f"rerun+http://127.0.0.1:{port}/proxy")
        out, err = training.communicate(timeout=300)
    finally:
        if training.poll() is None:
            training.kill()
    assert training.returncode == 0, err[-2000:]
    assert f"live view: rerun --bind 127.0.0.1 --connect rerun+http://127.0.0.1:{port}" in out
    headless.wait_loaded(viewer, "iteration")
    iteration = next(t for r in viewer.get_state().recordings for t in r.timelines
                     if t.name == "iteration")
    assert (iteration.start, iteration.end) == (1, ITERATIONS)
    entities = {e.entity_path.lstrip("/") for e in viewer.get_recording_schema(
        paths_only=True).entities}
    assert {"train/J_clane", "train/lambda_lane", "train/loss_objective", "world/robot",
            "world/robot/camera/image"} <= entities
    assert not [p for p in headless.view_problems(viewer) if p.severity == "error"]
