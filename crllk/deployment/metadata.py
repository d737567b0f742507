"""What an exported policy's metadata says the pilot must feed it, read with bounds.

An ONNX file is input like any other: its ``crllk.*`` metadata (:mod:`.export`) is checked
before the pilot allocates anything from it (the images a policy remembers) or divides by it
(the image's size), and against the graph's own input and output. Each problem is one line,
``<file>: crllk.<field>: <problem>`` (:class:`~crllk.errors.ConfigError`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from crllk.deployment.onnx_names import (
    EXPORTABLE_ACTIONS,
    INPUT,
    METADATA_PREFIX,
    OBSERVATIONS,
    OUTPUT,
)
from crllk.errors import ConfigError

MAX_METADATA_CHARS = 200
"""Longest metadata value parsed as JSON (characters); the export writes at most about 20."""
MAX_IMAGE_SIDE = 640
"""Largest height or width of a policy's image (pixels): the camera's 640×480 frames give no
more (training uses 30×40)."""
MAX_STATE_FEATURES = 1024
"""Most state features a policy may read (the lane-keeping state has a few dozen)."""
MAX_HISTORY_IMAGES = 16
"""Most camera images a policy may read at once (``obs.history``; memory runs use 2 to 4)."""
MAX_HISTORY_STEPS = 300
"""Most control steps the oldest image a policy reads may lie back (``(history - 1) *
history_stride``): 10 s at the 30 Hz control rate."""
MAX_HISTORY_BYTES = 64 * 2**20
"""Most memory the images a policy remembers may take (bytes; 64 MiB). A 30×40 policy with the
longest history above takes about 1 MiB."""
MAX_SUPERSAMPLE = 16
"""Largest ``crllk.supersample``: 16 renders a 30×40 image at the camera's 640×480."""

_INPUT_TYPE = {"pixels": "tensor(uint8)", "state": "tensor(float)"}
"""The graph input's type for each kind of observation (:mod:`.export`)."""


@dataclass(frozen=True)
class PolicyMetadata:
    """An exported policy's metadata, checked (:func:`read_metadata`)."""

    observation: str
    """``pixels`` or ``state``."""
    action: str
    observation_shape: tuple[int, ...]
    """The graph input's shape: ``(height, width, 3 * images)`` or ``(features,)``."""
    history: tuple[int, int]
    """Images a pixel policy reads at once and control steps between them."""
    supersample: int | None
    """How much larger training rendered its images (None for exports that do not say)."""


def read_metadata(metadata: Mapping[str, str], source: str) -> PolicyMetadata:
    """The checked metadata (keys without the ``crllk.`` prefix) of the policy in ``source``.

    Raises:
        ConfigError: ``<source>: metadata: not a crllk policy`` without the keys the export
            writes, else ``<source>: crllk.<field>: <problem>`` for the first bad value.
    """
    if any(key not in metadata for key in ("observation", "action", "observation_shape")):
        raise ConfigError(source, "metadata", "not a crllk policy (export it with "
                          "python -m crllk.export)")
    observation = _one_of(metadata, "observation", OBSERVATIONS, source)
    action = _one_of(metadata, "action", EXPORTABLE_ACTIONS, source)
    history = _whole_numbers(metadata, "history", source, default=[1, 1])
    if len(history) != 2:
        raise _error(source, "history", f"expected [images, stride], got {_shown(history)}")
    images, stride = history
    _check_range(source, "history", "images", images, 1, MAX_HISTORY_IMAGES)
    _check_range(source, "history", "stride", stride, 1, MAX_HISTORY_STEPS)
    if (images - 1) * stride > MAX_HISTORY_STEPS:
        raise _error(source, "history", f"{images} images {stride} steps apart reach "
                     f"{(images - 1) * stride} steps back, more than {MAX_HISTORY_STEPS}")
    if observation == "state" and images != 1:
        raise _error(source, "history", f"a state policy reads one observation, got {images}")
    shape = tuple(_whole_numbers(metadata, "observation_shape", source))
    if observation == "pixels":
        _check_image_shape(shape, images, stride, source)
    elif len(shape) != 1:
        raise _error(source, "observation_shape", f"expected [features] for a state policy, "
                     f"got {list(shape)}")
    else:
        _check_range(source, "observation_shape", "features", shape[0], 1, MAX_STATE_FEATURES)
    supersample = None
    if "supersample" in metadata:
        supersample = _whole_numbers(metadata, "supersample", source, single=True)[0]
        _check_range(source, "supersample", "the factor", supersample, 1, MAX_SUPERSAMPLE)
    return PolicyMetadata(observation, action, shape, (images, stride), supersample)


def check_graph(inputs: list[Any], outputs: list[Any], metadata: PolicyMetadata,
                source: str) -> None:
    """Checks the graph's inputs and outputs (ONNX Runtime's ``NodeArg``: ``name``, ``type``,
    ``shape``) against its metadata: one input of the observation's type and shape, and a
    float output of two duties first.

    Raises:
        ConfigError: ``<source>: crllk.observation_shape: ...`` (or another field) one line.
    """
    expected = _INPUT_TYPE[metadata.observation]
    if len(inputs) != 1 or inputs[0].name != INPUT or inputs[0].type != expected:
        found = ", ".join(f"{node.name} {node.type}" for node in inputs[:3])
        raise _error(source, "observation", f"a {metadata.observation} policy has one input, "
                     f"{INPUT} {expected}; the graph's: {found or 'none'}")
    if not _same_shape(inputs[0].shape, metadata.observation_shape):
        raise _error(source, "observation_shape", f"{list(metadata.observation_shape)}, but the "
                     f"graph's input is {_shown(inputs[0].shape)}")
    if (not outputs or outputs[0].name != OUTPUT or outputs[0].type != "tensor(float)"
            or not _same_shape(outputs[0].shape, (2,))):
        found = (f"{outputs[0].name} {outputs[0].type} {_shown(outputs[0].shape)}" if outputs
                 else "none")
        raise ConfigError(source, "graph output", f"expected {OUTPUT} tensor(float) [2] (left "
                          f"and right duty), got {found}")


def _check_image_shape(shape: tuple[int, ...], images: int, stride: int, source: str) -> None:
    """A pixel policy's ``(height, width, 3 * images)`` within the bounds."""
    if len(shape) != 3:
        raise _error(source, "observation_shape", f"expected [height, width, channels] for a "
                     f"pixel policy, got {list(shape)}")
    height, width, channels = shape
    _check_range(source, "observation_shape", "the height", height, 1, MAX_IMAGE_SIDE)
    _check_range(source, "observation_shape", "the width", width, 1, MAX_IMAGE_SIDE)
    if channels != 3 * images:
        raise _error(source, "observation_shape", f"{channels} channels, but "
                     f"{METADATA_PREFIX}history reads {images} RGB image(s): {3 * images}")
    remembered = ((images - 1) * stride + 1) * height * width * 3
    if remembered > MAX_HISTORY_BYTES:
        raise _error(source, "observation_shape", f"the images remembered would take "
                     f"{remembered} bytes, more than {MAX_HISTORY_BYTES}")


def _one_of(metadata: Mapping[str, str], key: str, choices: tuple[str, ...],
            source: str) -> str:
    value = metadata[key]
    if value not in choices:
        raise _error(source, key, f"expected one of {', '.join(choices)}, got {_shown(value)}")
    return value


def _whole_numbers(metadata: Mapping[str, str], key: str, source: str, *,
                   default: list[int] | None = None, single: bool = False) -> list[int]:
    """``metadata[key]`` read as a JSON list of whole numbers (or one, when ``single``)."""
    if key not in metadata:
        return list(default or [])
    text = metadata[key]
    what = "a whole number" if single else "a list of whole numbers"
    if len(text) > MAX_METADATA_CHARS:
        raise _error(source, key, f"expected {what}, got {len(text)} characters")
    try:
        value = json.loads(text)
    except (ValueError, RecursionError):
        raise _error(source, key, f"expected {what}, got {_shown(text)}") from None
    values = [value] if single else value
    if not isinstance(values, list) or not all(
            isinstance(v, int) and not isinstance(v, bool) for v in values):
        raise _error(source, key, f"expected {what}, got {_shown(text)}")
    return values


def _check_range(source: str, key: str, what: str, value: int, least: int, most: int) -> None:
    if not least <= value <= most:
        raise _error(source, key, f"{what} must be from {least} to {most}, got {value}")


def _same_shape(dims: list[Any], shape: tuple[int, ...]) -> bool:
    """Whether a graph's dimensions (numbers, or names for free ones) fit ``shape``."""
    return len(dims) == len(shape) and all(
        not isinstance(d, int) or d == n for d, n in zip(dims, shape, strict=True))


def _error(source: str, key: str, problem: str) -> ConfigError:
    return ConfigError(source, METADATA_PREFIX + key, problem)


def _shown(value: object, limit: int = 40) -> str:
    """``value`` as it reads (a string quoted), cut to ``limit`` characters."""
    text = repr(value) if isinstance(value, str) else json.dumps(value, default=str)
    return text if len(text) <= limit else text[:limit] + "..."
