"""The robot path fails safe: values that are not finite give a stop, images are refused by
their header's size before they are decoded, a policy file's metadata is checked with bounds,
the node's watchdog stops the wheels when frames stop, and bad input is one short line.

The policies are real ONNX files, exported from tiny networks with the export's own metadata
(no training): a state policy whose duties are ``features[:2] / features[2]`` and a pixel
policy whose duties are the mean red and green over the mean blue, so that a zero divisor gives
outputs that are not finite."""

from __future__ import annotations

import io
import logging
import math
import re
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from PIL import Image

from crllk import deploy
from crllk.cli import exit_status
from crllk.deployment import metadata as bounds
from crllk.deployment import ros_node
from crllk.deployment.export import export_onnx
from crllk.deployment.pilot import (
    NON_FINITE_INPUT,
    NON_FINITE_OUTPUT,
    STOP,
    WARN_EVERY,
    Faults,
    Pilot,
    WheelCommand,
)
from crllk.deployment.ros_node import BAD_FRAME, FRAME_TIMEOUT_S, NO_FRAME, DriveLoop
from crllk.errors import ConfigError
from crllk.images import MAX_FRAME_BYTES, MAX_FRAME_PIXELS, decode_image

FEATURES = 5
"""State features of the tiny state policy."""
SHORT = 200
"""Longest one-line message the tests accept (characters)."""


class Ratio(torch.nn.Module):
    """State policy: ``features[:2] / features[2]``."""

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return features[:2] / features[2]


class ColourRatio(torch.nn.Module):
    """Pixel policy: mean red and mean green over mean blue."""

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        mean = image.float().mean(dim=(0, 1))
        return torch.stack([mean[0], mean[1]]) / mean[2]


@pytest.fixture(scope="module")
def state_policy(tmp_path_factory) -> Path:
    return export_onnx(Ratio().eval(), {"observation": "state", "action": "continuous",
                                        "observation_shape": f"[{FEATURES}]",
                                        "history": "[1, 1]"},
                       tmp_path_factory.mktemp("state") / "state.onnx")


@pytest.fixture(scope="module")
def pixel_policy(tmp_path_factory) -> Path:
    return export_onnx(ColourRatio().eval(), {"observation": "pixels", "action": "discrete",
                                              "observation_shape": "[30, 40, 3]",
                                              "history": "[1, 1]", "supersample": "2"},
                       tmp_path_factory.mktemp("pixels") / "pixels.onnx")


def _encoded(image: np.ndarray, format: str = "JPEG") -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format=format)
    return buffer.getvalue()


def _camera_jpeg(seed: int = 0) -> bytes:
    """A 640×480 JPEG with blue in every pixel (the pixel policy's divisor)."""
    image = np.random.default_rng(seed).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    image[..., 2] |= 64
    return _encoded(image)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _png_claiming(width: int, height: int) -> bytes:
    """A PNG whose header (IHDR, correct CRC) claims ``width`` × ``height`` RGB pixels, with
    no pixel data: decoding it would fail, so an error about its size shows it was refused
    before decoding."""
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)
            + _chunk(b"IDAT", zlib.compress(b"")) + _chunk(b"IEND", b""))


def _jpeg_claiming(width: int, height: int) -> bytes:
    """A real 64×48 JPEG whose frame header (SOF0) is edited to claim ``width`` × ``height``."""
    data = bytearray(_encoded(np.full((48, 64, 3), 90, np.uint8)))
    sof = data.index(b"\xff\xc0")
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def _one_line(error: BaseException) -> str:
    """The error's one short line; a file path in it is not counted (it depends on the folder)."""
    text = str(error)
    message = re.sub(r"/\S+?\.(onnx|json|jpg|png):", "FILE:", text)
    assert "\n" not in text and len(message) <= SHORT, text
    return text


def _command_error(capsys, main, argv: list[str]) -> str:
    """The one line a command prints for bad input (status 2, no traceback)."""
    capsys.readouterr()
    try:
        status = exit_status(lambda: main(argv))
    except SystemExit as exit_info:
        status = exit_info.code
    err = capsys.readouterr().err.strip()
    assert status == 2 and err.startswith("error: "), err
    assert len(err.splitlines()) == 1 and "Traceback" not in err and len(err) <= 2 * SHORT, err
    return err


# Values that are not finite ----------------------------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e39])  # 1e39: inf as float32
def test_state_features_not_finite_give_a_counted_stop(state_policy, bad):
    pilot = Pilot.from_onnx(state_policy)
    assert pilot.step(np.array([1.0, -0.5, 2.0, 0, 0])) == WheelCommand(0.5, -0.25)
    features = np.array([1.0, 1.0, 1.0, 0.0, 0.0])
    features[3] = bad
    assert pilot.step(features) == STOP
    assert pilot.faults.counts == {NON_FINITE_INPUT: 1} and pilot.faults.total == 1


@pytest.mark.parametrize("divisor", [0.0, -0.0])
def test_a_policy_output_not_finite_gives_a_counted_stop(state_policy, divisor):
    pilot = Pilot.from_onnx(state_policy)
    assert pilot.step([1.0, 0.0, divisor, 0, 0]) == STOP  # inf and nan
    assert pilot.step([0.0, 0.0, divisor, 0, 0]) == STOP  # nan and nan
    assert pilot.faults.counts == {NON_FINITE_OUTPUT: 2}


def test_an_image_policy_output_not_finite_gives_a_stop(pixel_policy):
    pilot = Pilot.from_onnx(pixel_policy)
    red = np.zeros((480, 640, 3), np.uint8)
    red[..., 0] = 200  # no blue: the policy divides by zero
    assert pilot.step(_encoded(red, "PNG")) == STOP
    assert pilot.step(red) == STOP
    assert pilot.faults.counts == {NON_FINITE_OUTPUT: 2}
    command = pilot.step(_camera_jpeg())
    assert math.isfinite(command.vel_left) and command != STOP


def test_the_pilot_never_returns_a_command_that_is_not_finite(state_policy):
    pilot = Pilot.from_onnx(state_policy)
    rng = np.random.default_rng(0)
    specials = np.array([math.nan, math.inf, -math.inf, 0.0, 1e-40, 1e30, -1e30])
    for _ in range(300):
        features = rng.normal(size=FEATURES) * 10.0 ** rng.integers(-3, 4)
        mask = rng.random(FEATURES) < 0.3
        features[mask] = rng.choice(specials, size=mask.sum())
        command = pilot.step(features)
        assert all(math.isfinite(v) and -1 <= v <= 1
                   for v in (command.vel_left, command.vel_right)), (features, command)
    assert pilot.faults.total > 0


def test_stops_are_logged_with_their_count_not_once_a_frame(state_policy, caplog):
    pilot = Pilot.from_onnx(state_policy)
    frames = 3 * WARN_EVERY + 5
    with caplog.at_level(logging.WARNING, logger="crllk.deployment.pilot"):
        for _ in range(frames):
            assert pilot.step(np.full(FEATURES, math.nan)) == STOP
    messages = [record.getMessage() for record in caplog.records]
    assert pilot.faults.counts[NON_FINITE_INPUT] == frames
    assert len(messages) == 1 + frames // WARN_EVERY  # the first, then every WARN_EVERY-th
    assert messages[0] == f"{state_policy}: {NON_FINITE_INPUT}: wheels stopped (1 so far)"
    assert messages[-1].endswith(f"({3 * WARN_EVERY} so far)")


# Images bounded before decoding ------------------------------------------------------------


@pytest.mark.parametrize("frame", [
    _png_claiming(100_000, 100_000),  # 10^10 pixels: Pillow refuses it as it opens
    _png_claiming(9_500, 9_500),  # 90 Mpx: Pillow only warns
    _png_claiming(2561, 1920),  # just over the bound, far under Pillow's
    _jpeg_claiming(60_000, 60_000),
    _jpeg_claiming(3000, 2000),
], ids=["png-1e10", "png-90M", "png-over-bound", "jpeg-3.6G", "jpeg-6M"])
def test_too_large_an_image_is_refused_from_its_header(pixel_policy, frame):
    pilot = Pilot.from_onnx(pixel_policy)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no DecompressionBombWarning either
        with pytest.raises(ConfigError) as error:
            pilot.step(frame, "frames/big.png")
    message = _one_line(error.value)
    assert message.startswith("frames/big.png: frame: ") and str(MAX_FRAME_PIXELS) in message
    assert "decode" not in message  # refused, not decoded and failed


def test_the_bound_holds_without_pillows_own(monkeypatch):
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", None)  # Pillow's check off
    with pytest.raises(ConfigError, match="100000×100000 pixels, more than"):
        decode_image(_png_claiming(100_000, 100_000))


def test_images_within_the_bounds_decode():
    assert MAX_FRAME_PIXELS >= 16 * 640 * 480
    largest = _encoded(np.zeros((1920, 2560, 3), np.uint8), "PNG")
    assert decode_image(largest).shape == (1920, 2560, 3)
    assert decode_image(_camera_jpeg()).shape == (480, 640, 3)


@pytest.mark.parametrize(("frame", "words"), [
    (b"\0" * (MAX_FRAME_BYTES + 1), "bytes, more than"),
    (b"not a jpeg", "not an image (JPEG or PNG)"),
    (_camera_jpeg()[:5000], "cannot decode the JPEG image"),
    (_encoded(np.zeros((48, 64, 3), np.uint8), "GIF"), "not an image (JPEG or PNG)"),
    (_encoded(np.zeros((48, 64, 3), np.uint8), "BMP"), "not an image (JPEG or PNG)"),
], ids=["too-many-bytes", "no-image", "truncated", "gif", "bmp"])
def test_frames_that_cannot_be_read_are_one_line(frame, words):
    with pytest.raises(ConfigError) as error:
        decode_image(frame, "camera")
    assert words in _one_line(error.value) and str(error.value).startswith("camera: frame: ")


# Metadata checked with bounds ---------------------------------------------------------------


def _with_metadata(policy: Path, out: Path, **values: str) -> Path:
    """A copy of the exported ``policy`` whose ``crllk.<key>`` metadata is set to ``values``."""
    model = onnx.load(policy)
    kept = {e.key: e.value for e in model.metadata_props}
    kept.update({f"crllk.{key}": value for key, value in values.items()})
    del model.metadata_props[:]
    for key, value in kept.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(model, out)
    return out


BAD_METADATA = [
    ("observation_shape", {"observation_shape": "[0, 0, 3]"}, "the height must be from 1 to"),
    ("observation_shape", {"observation_shape": "[30, 100000, 3]"}, "the width must be from"),
    ("observation_shape", {"observation_shape": "[30, 40]"}, "expected [height, width, channels]"),
    ("observation_shape", {"observation_shape": "[30.0, 40, 3]"}, "a list of whole numbers"),
    ("observation_shape", {"observation_shape": "[true, 40, 3]"}, "a list of whole numbers"),
    ("observation_shape", {"observation_shape": "[" * 150 + "]" * 150}, "list of whole numbers"),
    ("observation_shape", {"observation_shape": "[" * 5000}, "5000 characters"),
    ("observation_shape", {"observation_shape": "[30, 40, 6]"}, "6 channels"),
    ("observation_shape", {"observation_shape": "[640, 640, 48]", "history": "[16, 20]"},
     "more than 67108864"),
    ("observation_shape", {"observation_shape": "[30, 40, 6]", "history": "[2, 1]"},
     "but the graph's input is [30, 40, 3]"),
    ("history", {"history": "[100000, 1]"}, "images must be from 1 to 16, got 100000"),
    ("history", {"history": "1e5"}, "a list of whole numbers"),
    ("history", {"history": "[1, 100000]"}, "stride must be from 1 to 300"),
    ("history", {"history": "[16, 30]"}, "450 steps back, more than 300"),
    ("history", {"history": "[2]"}, "expected [images, stride]"),
    ("history", {"history": "[0, 1]"}, "images must be from 1"),
    ("supersample", {"supersample": "1000"}, "from 1 to 16, got 1000"),
    ("supersample", {"supersample": "eight"}, "expected a whole number, got 'eight'"),
    ("observation", {"observation": "video"}, "expected one of pixels, state"),
    ("observation", {"observation": "state", "observation_shape": "[5]"},
     "a state policy has one input, observation tensor(float)"),
    ("action", {"action": "fly"}, "expected one of discrete, continuous, stoppable, duckietown"),
]


@pytest.mark.parametrize(("field", "values", "words"), BAD_METADATA,
                         ids=[f"{f}-{i}" for i, (f, _, _) in enumerate(BAD_METADATA)])
def test_metadata_out_of_bounds_is_one_line(pixel_policy, tmp_path, field, values, words):
    """Crafted metadata (a zero-sized image, a history of 1e5 images) is refused before
    anything is allocated from it: no ZeroDivisionError, no MemoryError."""
    crafted = _with_metadata(pixel_policy, tmp_path / "crafted.onnx", **values)
    with pytest.raises(ConfigError) as error:
        Pilot.from_onnx(crafted)
    message = _one_line(error.value)
    assert message.startswith(f"{crafted}: crllk.{field}: ") and words in message, message
    assert error.value.field == f"crllk.{field}"


def test_a_state_policy_with_a_history_is_refused(state_policy, tmp_path):
    crafted = _with_metadata(state_policy, tmp_path / "crafted.onnx", history="[2, 1]")
    with pytest.raises(ConfigError, match=r"crllk\.history: a state policy reads one"):
        Pilot.from_onnx(crafted)
    crafted = _with_metadata(state_policy, tmp_path / "wide.onnx", observation_shape="[5000]")
    with pytest.raises(ConfigError, match=f"from 1 to {bounds.MAX_STATE_FEATURES}, got 5000"):
        Pilot.from_onnx(crafted)


def test_a_graph_without_two_duties_is_refused(tmp_path):
    class Three(torch.nn.Module):
        def forward(self, features: torch.Tensor) -> torch.Tensor:
            return features[:3]

    policy = export_onnx(Three().eval(), {"observation": "state", "action": "discrete",
                                          "observation_shape": "[5]"}, tmp_path / "three.onnx")
    with pytest.raises(ConfigError) as error:
        Pilot.from_onnx(policy)
    assert "graph output: expected duty tensor(float) [2]" in _one_line(error.value)


# The wrong kind of input --------------------------------------------------------------------


def test_the_wrong_kind_of_input_is_one_short_line(state_policy, pixel_policy):
    state, pixels = Pilot.from_onnx(state_policy), Pilot.from_onnx(pixel_policy)
    jpeg = _camera_jpeg()
    assert len(jpeg) > 10 * SHORT
    cases = [
        (state, jpeg, f"expected {FEATURES} state features, got {len(jpeg)} bytes (an image?)"),
        (state, np.zeros((480, 640, 3), np.uint8),
         f"expected {FEATURES} state features, got uint8 of shape (480, 640, 3)"),
        (state, "x" * 20_000, f"expected {FEATURES} state features, got a str of 20000"),
        (state, [[1.0, 2.0], [3.0]], f"expected {FEATURES} state features, got a list of 2"),
        (pixels, np.zeros(FEATURES, np.float32),
         "expected RGB uint8 of shape (height, width, 3), got float32 of shape (5,)"),
        (pixels, [0.0] * FEATURES, "expected an image (JPEG or PNG bytes, or RGB uint8 of "
                                   "shape (height, width, 3)), got a list of 5"),
    ]
    for pilot, frame, words in cases:
        with pytest.raises(ConfigError) as error:
            pilot.step(frame, "camera")
        assert str(error.value) == f"camera: frame: {words}"
        _one_line(error.value)


# The node's watchdog, without ROS ------------------------------------------------------------


class FakeClock:
    """Seconds that move only when a test says so."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def drive(pixel_policy):
    """A :class:`DriveLoop` on the pixel policy, a fake clock and the commands it published."""
    clock, published = FakeClock(), []
    loop = DriveLoop(Pilot.from_onnx(pixel_policy), published.append, clock)
    return loop, clock, published


def test_the_watchdog_stops_the_wheels_when_frames_stop(drive, pixel_policy, monkeypatch):
    loop, clock, published = drive
    resets = []
    monkeypatch.setattr(loop.pilot, "reset", lambda: resets.append(clock.now))
    expected = Pilot.from_onnx(pixel_policy).step(_camera_jpeg())
    loop.on_frame(_camera_jpeg())
    clock.now += 0.01
    loop.on_tick()
    assert published == [expected] and expected != STOP
    for waited in (0.1, FRAME_TIMEOUT_S - 0.01):  # late, not yet stalled: the command holds
        clock.now += waited - (clock.now - 100.0)
        loop.on_tick()
    assert published == [expected] and not loop.stalled
    for _ in range(3):  # stalled: a stop at every tick, counted once
        clock.now += 1 / ros_node.CONTROL_RATE_HZ
        loop.on_tick()
    assert published[1:] == [STOP] * 3 and loop.stalled
    assert loop.faults.counts == {NO_FRAME: 1} and len(resets) == 1
    loop.on_frame(_camera_jpeg())  # frames again: it drives again
    loop.on_tick()
    assert published[-1] == expected and not loop.stalled


def test_the_watchdog_stops_a_node_that_never_got_a_frame(drive):
    loop, clock, published = drive
    loop.on_tick()
    assert published == []
    clock.now += FRAME_TIMEOUT_S + 0.01
    loop.on_tick()
    assert published == [STOP] and loop.faults.counts[NO_FRAME] == 1


def test_the_frame_timeout_is_configurable(pixel_policy):
    clock, published = FakeClock(), []
    loop = DriveLoop(Pilot.from_onnx(pixel_policy), published.append, clock,
                     frame_timeout_s=0.1)
    clock.now += 0.11
    loop.on_tick()
    assert published == [STOP]
    with pytest.raises(ValueError, match="frame_timeout_s must be above 0"):
        DriveLoop(loop.pilot, published.append, clock, frame_timeout_s=0.0)


@pytest.mark.parametrize("bad", [b"not a jpeg", _png_claiming(100_000, 100_000),
                                 _camera_jpeg()[:3000]], ids=["garbage", "bomb", "truncated"])
def test_the_node_stops_on_an_unreadable_frame_and_goes_on(drive, bad, caplog):
    loop, clock, published = drive
    with caplog.at_level(logging.WARNING, logger="crllk.deployment.pilot"):
        for _ in range(2):
            loop.on_frame(bad)
            loop.on_tick()
            clock.now += 0.03
    assert published == [STOP, STOP] and loop.faults.counts == {BAD_FRAME: 2}
    assert len(caplog.records) == 1  # the first; then every WARN_EVERY-th
    message = caplog.records[0].getMessage()
    assert message.startswith(f"{loop.pilot.source}: {BAD_FRAME}: wheels stopped (1 so far): "
                              "camera: frame: ")
    assert "\n" not in message and len(message) < 2 * SHORT
    loop.on_frame(_camera_jpeg())
    loop.on_tick()
    assert published[-1] != STOP and math.isfinite(published[-1].vel_left)


def test_faults_go_where_the_node_sends_them():
    seen: list[str] = []
    faults = Faults("node", seen.append, every=2)
    for _ in range(5):
        faults.record("kind", "why")
    assert seen == ["node: kind: wheels stopped (1 so far): why",
                    "node: kind: wheels stopped (2 so far): why",
                    "node: kind: wheels stopped (4 so far): why"]


def test_the_node_refuses_a_timeout_shorter_than_a_step(pixel_policy, capsys):
    err = _command_error(capsys, ros_node.main, ["--policy", str(pixel_policy), "--vehicle",
                                                 "duck", "--frame-timeout", "0.01"])
    assert "--frame-timeout: must be longer than one step" in err


# Commands given bad input --------------------------------------------------------------------


def _frames(folder: Path, *named: tuple[str, bytes]) -> Path:
    folder.mkdir()
    for name, data in named:
        (folder / name).write_bytes(data)
    return folder


def test_deploy_refuses_a_bomb_naming_the_file(pixel_policy, tmp_path, capsys):
    frames = _frames(tmp_path / "frames", ("000.jpg", _camera_jpeg()),
                     ("001.png", _png_claiming(100_000, 100_000)))
    err = _command_error(capsys, deploy.main, ["--policy", str(pixel_policy), "--frames",
                                               str(frames), "--out", str(tmp_path / "c.csv")])
    assert f"{frames / '001.png'}: frame: " in err and str(MAX_FRAME_PIXELS) in err


def test_deploy_refuses_too_large_a_file_before_reading_it(pixel_policy, tmp_path, capsys):
    frames = _frames(tmp_path / "frames")
    with (frames / "000.png").open("wb") as handle:
        handle.truncate(MAX_FRAME_BYTES + 1)  # sparse: nothing written, nothing read
    err = _command_error(capsys, deploy.main, ["--policy", str(pixel_policy), "--frames",
                                               str(frames), "--out", str(tmp_path / "c.csv")])
    assert f"{frames / '000.png'}: frame: {MAX_FRAME_BYTES + 1} bytes" in err


def test_deploy_with_a_state_policy_on_images_is_one_line(state_policy, tmp_path, capsys):
    frames = _frames(tmp_path / "frames", ("000.jpg", _camera_jpeg()))
    err = _command_error(capsys, deploy.main, ["--policy", str(state_policy), "--frames",
                                               str(frames), "--out", str(tmp_path / "c.csv")])
    assert f"{frames / '000.jpg'}: frame: expected {FEATURES} state features, got" in err


def test_deploy_with_crafted_metadata_is_one_line(pixel_policy, tmp_path, capsys):
    crafted = _with_metadata(pixel_policy, tmp_path / "crafted.onnx", history="[100000, 1]")
    frames = _frames(tmp_path / "frames", ("000.jpg", _camera_jpeg()))
    err = _command_error(capsys, deploy.main, ["--policy", str(crafted), "--frames", str(frames),
                                               "--out", str(tmp_path / "c.csv")])
    assert f"{crafted}: crllk.history: images must be from 1 to 16" in err


def test_deploy_counts_the_stops(pixel_policy, tmp_path, capsys):
    red = np.zeros((480, 640, 3), np.uint8)
    red[..., 0] = 200
    frames = _frames(tmp_path / "frames", ("000.jpg", _camera_jpeg()),
                     ("001.png", _encoded(red, "PNG")))
    out = tmp_path / "c.csv"
    assert exit_status(lambda: deploy.main(["--policy", str(pixel_policy), "--frames",
                                            str(frames), "--out", str(out)])) == 0
    rows = out.read_text().splitlines()
    assert rows[2].startswith("001.png,0.000000,0.000000,")
    assert f"1 of 2 frames gave a stop ({NON_FINITE_OUTPUT} 1)" in capsys.readouterr().out
