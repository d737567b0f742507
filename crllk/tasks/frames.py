"""Camera frames as the policy saw them in training, and the robot camera's frames prepared
the same way.

In training the robot camera is rendered at ``supersample`` times the policy's 30×40 and
box-averaged down (:func:`crllk.sim.physics.box_average`), RGB. A real frame goes the same way:
JPEG bytes (as the Duckiebot camera publishes them, 640×480) are decoded to RGB, never BGR; a
frame whose aspect ratio is not the policy's 4:3 is cropped to it about its centre; then it is
area-averaged down to 30×40 — exactly :func:`box_average` when the size is a whole multiple,
as 640×480 is (16×16 blocks), else PIL's box filter.
"""

from __future__ import annotations

import io
from collections.abc import Callable

import numpy as np
from PIL import Image

from crllk.errors import ConfigError
from crllk.sim.physics import box_average

POLICY_IMAGE = (30, 40)
"""Height and width (pixels) of the policy's camera image."""


def decode(frame: bytes | np.ndarray, source: str = "frame") -> np.ndarray:
    """An RGB uint8 H×W×3 array from JPEG (or PNG) bytes or an array (H×W×3 or H×W×4).

    Raises:
        ConfigError: for bytes that are no image, or an array of another shape or type.
    """
    if isinstance(frame, bytes | bytearray | memoryview):
        try:
            with Image.open(io.BytesIO(bytes(frame))) as image:
                return np.asarray(image.convert("RGB"))
        except (OSError, ValueError) as err:
            raise ConfigError(source, "frame", f"not an image: {err}") from None
    array = np.asarray(frame)
    if array.ndim != 3 or array.shape[2] not in (3, 4) or array.dtype != np.uint8:
        raise ConfigError(source, "frame", "expected RGB uint8 of shape (height, width, 3), got "
                          f"{array.dtype} of shape {array.shape}")
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
