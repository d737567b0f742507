"""The pilot: camera frames in, wheel commands out, through an exported policy.

``Pilot.from_onnx(path).step(frame)`` takes one camera frame, JPEG bytes as the Duckiebot camera
publishes them or an RGB array of any size, prepares it exactly as in training
(:func:`crllk.tasks.frames.policy_image`), runs the policy with ONNX Runtime and returns a
:class:`WheelCommand` whose ``vel_left`` and ``vel_right`` in [-1, 1] are the wheel duty cycles
the policy chose, the values of the robot's ``WheelsCmdStamped`` message. A state policy's
pilot takes the state features instead.

It fails safe: state features or a policy output that are not finite give :data:`STOP` (both
wheels 0), counted in :attr:`Pilot.faults` and logged as a warning the first time and every
:data:`WARN_EVERY` times after, so the pilot never returns a command that is not finite. A frame
that cannot be read (no image, too large an image, the wrong kind of input) raises a one-line
:class:`~crllk.errors.ConfigError`; the ROS 2 node stops the wheels on it and goes on. The
policy file's metadata is checked with bounds as it loads (:mod:`.metadata`).

A policy trained with a frame history (``obs.history``) reads its last images together; the
pilot keeps them (:class:`~crllk.tasks.frames.FrameHistory`), one per ``step``, so it must be
stepped at the control rate it was trained at (30 Hz, the camera's rate), and :meth:`Pilot.reset`
starts a new drive.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnxruntime

from crllk.deployment.metadata import check_graph, read_metadata
from crllk.deployment.onnx_names import INPUT, METADATA_PREFIX
from crllk.errors import ConfigError
from crllk.tasks.frames import FrameHistory, policy_image

SOURCE = "pilot"
WARN_EVERY = 30
"""A kind of stop is logged the first time and then every this many times, with its count
(once a second while it lasts at the 30 Hz control rate)."""
NON_FINITE_INPUT = "state features not finite"
NON_FINITE_OUTPUT = "policy output not finite"

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class WheelCommand:
    """Wheel duty cycles in [-1, 1], as ``duckietown_msgs/WheelsCmdStamped`` carries them."""

    vel_left: float
    vel_right: float


STOP = WheelCommand(0.0, 0.0)
"""Both wheels stopped: what the pilot and the node send when they cannot drive."""


class Faults:
    """How many times each kind of fault stopped the wheels (:attr:`counts`), logged as a
    warning ``<source>: <kind>: wheels stopped (<n> so far)[: <detail>]`` the first time and
    every ``every`` times after, not once per frame."""

    def __init__(self, source: str, warn: Callable[[str], object] | None = None,
                 every: int = WARN_EVERY):
        self.source = source
        self.warn = warn if warn is not None else _LOG.warning
        """Where the warnings go (a ROS node sets its own logger)."""
        self.every = every
        self.counts: Counter[str] = Counter()

    @property
    def total(self) -> int:
        """Stops of every kind."""
        return sum(self.counts.values())

    def record(self, kind: str, detail: str = "") -> None:
        """Counts one stop of ``kind`` and logs it if it is the first or an ``every``-th."""
        self.counts[kind] += 1
        count = self.counts[kind]
        if count == 1 or count % self.every == 0:
            self.warn(f"{self.source}: {kind}: wheels stopped ({count} so far)"
                      + (f": {detail}" if detail else ""))


class Pilot:
    """Turns frames into wheel commands with one exported policy (see the module docstring)."""

    def __init__(self, session: onnxruntime.InferenceSession, metadata: dict[str, str],
                 source: str = SOURCE, faults: Faults | None = None):
        """The pilot of the policy ``session`` runs, its ``metadata`` (keys without
        ``crllk.``) checked (:mod:`.metadata`); ``source`` names it in messages.

        Raises:
            ConfigError: ``<source>: crllk.<field>: <problem>`` for metadata out of its bounds
                or unlike the graph.
        """
        checked = read_metadata(metadata, source)
        check_graph(session.get_inputs(), session.get_outputs(), checked, source)
        self.session = session
        self.source = source
        self.observation = checked.observation
        self.action = checked.action
        self.observation_shape = checked.observation_shape
        count, stride = checked.history
        self.history = (FrameHistory(1, (*self.observation_shape[:2], 3), count, stride)
                        if self.observation == "pixels" else None)
        """The images the policy remembers (pixel policies)."""
        self.supersample = checked.supersample
        """How much larger training rendered its images before averaging them down (None for
        exports that do not say)."""
        self.metadata = metadata
        self.faults = faults if faults is not None else Faults(source)
        """The stops for features or outputs that are not finite (and the node's own)."""
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

    def observation_of(self, frame: bytes | np.ndarray, source: str | None = None) -> np.ndarray:
        """What the policy reads of ``frame``: the 30×40 image, or the state features.

        Raises:
            ConfigError: ``<source>: frame: <problem>`` (``source`` defaults to the policy's
                file) for a frame that is no image, too large an image or the wrong kind of
                input; one short line, never the frame's bytes.
        """
        source = self.source if source is None else source
        if self.observation == "pixels":
            if not isinstance(frame, bytes | bytearray | memoryview | np.ndarray):
                raise ConfigError(source, "frame", "expected an image (JPEG or PNG bytes, or RGB "
                                  f"uint8 of shape (height, width, 3)), got {_kind(frame)}")
            return policy_image(frame, self.observation_shape[:2], source)
        expected = f"expected {self.observation_shape[0]} state features"
        if isinstance(frame, bytes | bytearray | memoryview):
            raise ConfigError(source, "frame", f"{expected}, got {_kind(frame)} (an image?)")
        if isinstance(frame, str):
            raise ConfigError(source, "frame", f"{expected}, got {_kind(frame)}")
        try:
            with np.errstate(over="ignore"):  # too large for float32: inf, a stop in step
                features = np.asarray(frame, dtype=np.float32)
        except (TypeError, ValueError):
            raise ConfigError(source, "frame", f"{expected}, got {_kind(frame)}") from None
        if features.shape != self.observation_shape:
            raise ConfigError(source, "frame", f"{expected}, got {_kind(frame)}")
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

    def step(self, frame: bytes | np.ndarray, source: str | None = None) -> WheelCommand:
        """The wheel command for the next frame of a drive; :data:`STOP` (counted in
        :attr:`faults`) for state features or a policy output that are not finite.

        Raises:
            ConfigError: for a frame that cannot be read (:meth:`observation_of`).
        """
        observation = self.observation_of(frame, source)
        if observation.dtype.kind == "f" and not np.isfinite(observation).all():
            self.faults.record(NON_FINITE_INPUT)
            return STOP
        duty = np.asarray(self.duty(self.remember(observation)))
        if duty.shape != (2,) or not np.isfinite(duty).all():
            self.faults.record(NON_FINITE_OUTPUT)
            return STOP
        left, right = np.clip(duty, -1.0, 1.0).tolist()
        return WheelCommand(vel_left=left, vel_right=right)


def _kind(frame: object) -> str:
    """What ``frame`` is, in a few words (never its contents)."""
    if isinstance(frame, np.ndarray):
        return f"{frame.dtype} of shape {frame.shape}"
    if isinstance(frame, bytes | bytearray | memoryview):
        return f"{len(frame)} bytes"
    try:
        return f"a {type(frame).__name__} of {len(frame)}"  # type: ignore[arg-type]
    except TypeError:
        return f"a {type(frame).__name__}"
