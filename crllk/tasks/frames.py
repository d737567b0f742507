"""Camera frames as the policy saw them in training, and the robot camera's frames prepared
the same way.

In training the robot camera is rendered at ``supersample`` times the policy's 30×40 and
box-averaged down (:func:`crllk.sim.physics.box_average`), RGB. A real frame goes the same way:
JPEG bytes (as the Duckiebot camera publishes them, 640×480) are decoded to RGB, never BGR; a
frame whose aspect ratio is not the policy's 4:3 is cropped to it about its centre; then it is
area-averaged down to 30×40 — exactly :func:`box_average` when the size is a whole multiple,
as 640×480 is (16×16 blocks), else PIL's box filter.

A policy with a memory reads several recent images at once (:class:`FrameHistory`), kept the
same way by the training env and by the pilot.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Sequence

import numpy as np
from PIL import Image

from crllk.errors import ConfigError
from crllk.images import box_average, check_frame_pixels, decode_image

POLICY_IMAGE = (30, 40)
"""Height and width (pixels) of the policy's camera image."""


def decode(frame: bytes | np.ndarray, source: str = "frame") -> np.ndarray:
    """An RGB uint8 H×W×3 array from JPEG (or PNG) bytes or an array (H×W×3, or H×W×4 whose
    alpha is dropped), either at most :data:`crllk.images.MAX_FRAME_PIXELS`.

    Raises:
        ConfigError: for bytes that are no image or too large an image
            (:func:`crllk.images.decode_image`), or an array of another shape or type, or
            larger.
    """
    if isinstance(frame, bytes | bytearray | memoryview):
        return decode_image(bytes(frame), source)
    array = np.asarray(frame)
    if array.ndim != 3 or array.shape[2] not in (3, 4) or array.dtype != np.uint8:
        raise ConfigError(source, "frame", "expected RGB uint8 of shape (height, width, 3), got "
                          f"{array.dtype} of shape {array.shape}")
    check_frame_pixels(array.shape[1], array.shape[0], source)
    return array[:, :, :3]


def crop_to_aspect(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """The largest centred crop of ``image`` with the aspect ratio ``width / height``."""
    rows, columns = image.shape[:2]
    if rows * width > columns * height:  # too tall
        keep = round(columns * height / width)
        top = (rows - keep) // 2
        return image[top:top + keep]
    keep = round(rows * width / height)
    left = (columns - keep) // 2
    return image[:, left:left + keep]


def policy_image(frame: bytes | np.ndarray, size: tuple[int, int] = POLICY_IMAGE,
                 source: str = "frame") -> np.ndarray:
    """``frame`` as the policy's uint8 RGB image of ``size`` (height, width)."""
    height, width = size
    image = crop_to_aspect(decode(frame, source), height, width)
    rows, columns = image.shape[:2]
    if rows < height or columns < width:
        raise ConfigError(source, "frame", f"{columns}×{rows} is smaller than the policy's "
                          f"{width}×{height}")
    if rows % height == 0 and columns % width == 0 and rows // height == columns // width:
        factor = rows // height
        return box_average(np.ascontiguousarray(image), factor) if factor > 1 else image.copy()
    return np.asarray(Image.fromarray(image).resize((width, height), Image.Resampling.BOX))


ROBOT_CAMERA = (480, 640)
"""Height and width of the Duckiebot camera's frames (pixels)."""
JPEG_QUALITY = 90
"""Quality of the JPEG frames :func:`robot_camera_image` encodes, as a camera publishes them."""


def robot_camera_image(render: Callable[[int, int], np.ndarray], size: tuple[int, int],
                       quality: int = JPEG_QUALITY) -> np.ndarray:
    """The policy's image of a frame taken as the robot's camera takes it: ``render(height,
    width)`` at 640x480, JPEG-encoded at ``quality``, then prepared as the pilot prepares it
    (:func:`policy_image`)."""
    buffer = io.BytesIO()
    Image.fromarray(render(*ROBOT_CAMERA)).save(buffer, format="JPEG", quality=quality)
    return policy_image(buffer.getvalue(), size)


class FrameHistory:
    """The recent camera images of ``num`` robots, stacked as a policy with a memory reads them.

    It keeps the last ``(count - 1) * stride + 1`` images of each robot and shows ``count`` of
    them, ``stride`` control steps apart, newest first, along the channels: ``[num, H, W,
    3 * count]``, channels ``3k .. 3k + 2`` being the RGB image of ``k * stride`` steps ago. At
    an episode's start (:meth:`restart`) every slot holds its first image. ``count=1`` is the
    plain image.
    """

    def __init__(self, num: int, image_shape: tuple[int, int, int], count: int = 1,
                 stride: int = 1):
        if count < 1 or stride < 1:
            raise ValueError(f"count and stride must be at least 1, got {count}, {stride}")
        self.count, self.stride = count, stride
        self.images = np.zeros((num, (count - 1) * stride + 1, *image_shape), np.uint8)
        """Every kept image, ``[num, slots, H, W, 3]``, the newest in slot 0."""

    @property
    def channels(self) -> int:
        return self.count * self.images.shape[-1]

    def restart(self, indices: Sequence[int], images: np.ndarray) -> None:
        """Robots ``indices`` start an episode: all their slots hold ``images`` (one each)."""
        self.images[list(indices)] = np.asarray(images)[:, None]

    def push(self, images: np.ndarray) -> None:
        """Every robot's newest image (``[num, H, W, 3]``), after one control step."""
        self.images[:, 1:] = self.images[:, :-1]
        self.images[:, 0] = images

    def stacked(self) -> np.ndarray:
        """What the policy reads: ``[num, H, W, 3 * count]`` uint8 (a new array)."""
        chosen = self.images[:, ::self.stride]
        num, _, height, width, _ = chosen.shape
        return np.moveaxis(chosen, 1, 3).reshape(num, height, width, self.channels)
