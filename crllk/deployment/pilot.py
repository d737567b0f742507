"""The pilot: camera frames in, wheel commands out, through an exported policy.

``Pilot.from_onnx(path).step(frame)`` takes one camera frame, JPEG bytes as the Duckiebot camera
publishes them or an RGB array of any size, prepares it exactly as in training
(:func:`crllk.tasks.frames.policy_image`), runs the policy with ONNX Runtime and returns a
:class:`WheelCommand` whose ``vel_left`` and ``vel_right`` in [-1, 1] are the wheel duty cycles
the policy chose, the values of the robot's ``WheelsCmdStamped`` message. A state policy's
pilot takes the state features instead.

A policy trained with a frame history (``obs.history``) reads its last images together; the
pilot keeps them (:class:`~crllk.tasks.frames.FrameHistory`), one per ``step``, so it must be
stepped at the control rate it was trained at (30 Hz, the camera's rate), and :meth:`Pilot.reset`
starts a new drive.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnxruntime

from crllk.deployment.onnx_names import INPUT, METADATA_PREFIX
from crllk.errors import ConfigError
from crllk.tasks.frames import FrameHistory, policy_image

SOURCE = "pilot"


@dataclass(frozen=True)
class WheelCommand:
    """Wheel duty cycles in [-1, 1], as ``duckietown_msgs/WheelsCmdStamped`` carries them."""

    vel_left: float
    vel_right: float


class Pilot:
    """Turns frames into wheel commands with one exported policy (see the module docstring)."""

    def __init__(self, session: onnxruntime.InferenceSession, metadata: dict[str, str],
                 source: str = SOURCE):
        self.session = session
        self.source = source
        try:
            self.observation = metadata["observation"]
            self.action = metadata["action"]
            self.observation_shape = tuple(json.loads(metadata["observation_shape"]))
            count, stride = json.loads(metadata.get("history", "[1, 1]"))
            self.history = (FrameHistory(1, (*self.observation_shape[:2], 3), count, stride)
                            if self.observation == "pixels" else None)
            """The images the policy remembers (pixel policies)."""
            supersample = metadata.get("supersample")
            self.supersample = None if supersample is None else int(supersample)
            """How much larger training rendered its images before averaging them down (None
            for exports that do not say)."""
            if self.supersample is not None and self.supersample < 1:
                raise ValueError(supersample)
        except (KeyError, ValueError, TypeError):
            raise ConfigError(source, "metadata", "not a crllk policy (export it with "
                              "python -m crllk.export)") from None
        self.metadata = metadata
        self._fresh = True

    def reset(self) -> None:
        """Forget the images seen: the next frame starts a drive (fills the whole history)."""
        self._fresh = True

    @classmethod
    def from_onnx(cls, path: str | Path, threads: int = 1) -> Pilot:
        """The pilot of the policy exported to ``path``, on ``threads`` CPU threads.

        Raises:
            ConfigError: if ``path`` is missing or not an exported crllk policy.
        """
        path = Path(path)
        if not path.is_file():
            raise ConfigError(path, "policy", "no such file")
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
        try:
            session = onnxruntime.InferenceSession(str(path), options,
                                                   providers=["CPUExecutionProvider"])
        except Exception as err:  # ONNX Runtime raises its own exception types
            reason = " ".join(str(err).split())[:200]
            raise ConfigError(path, "policy", f"not an ONNX model: {reason}") from None
        properties = session.get_modelmeta().custom_metadata_map
        metadata = {key.removeprefix(METADATA_PREFIX): value for key, value in properties.items()
                    if key.startswith(METADATA_PREFIX)}
        return cls(session, metadata, str(path))

    def observation_of(self, frame: bytes | np.ndarray) -> np.ndarray:
        """What the policy reads of ``frame``: the 30×40 image, or the state features."""
        if self.observation == "pixels":
            return policy_image(frame, self.observation_shape[:2], self.source)
        features = np.asarray(frame, dtype=np.float32)
        if features.shape != self.observation_shape:
            raise ConfigError(self.source, "frame", f"expected {self.observation_shape[0]} state "
                              f"features, got an array of shape {features.shape}")
        return features

    def duty(self, observation: np.ndarray) -> np.ndarray:
        """The policy's wheel duties (left, right) for an observation it reads as it is."""
        return self.session.run(None, {INPUT: observation})[0]

    def remember(self, observation: np.ndarray) -> np.ndarray:
        """The policy's input after one more observation (:meth:`observation_of`): pixel
        policies stack it with the images they remember."""
        if self.history is None:
            return observation
        if self._fresh:
            self.history.restart([0], observation[None])
            self._fresh = False
        else:
            self.history.push(observation[None])
        return self.history.stacked()[0]

    def step(self, frame: bytes | np.ndarray) -> WheelCommand:
        """The wheel command for the next frame of a drive."""
        observation = self.remember(self.observation_of(frame))
        left, right = np.clip(self.duty(observation), -1.0, 1.0).tolist()
        return WheelCommand(vel_left=left, vel_right=right)
