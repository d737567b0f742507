"""Image arithmetic shared by the simulator's renders and the robot's camera frames, and the
decoding of camera frames with their size bounded before any pixel is decoded (numpy and
Pillow only, so that the pilot on a robot needs nothing heavier)."""

from __future__ import annotations

import io
import struct
import warnings

import numpy as np
from PIL import Image, UnidentifiedImageError

from crllk.errors import ConfigError

_STRIDED_FACTOR_MAX = 4
"""Largest factor :func:`box_average` sums as strided sub-images (faster up to here)."""

MAX_FRAME_PIXELS = 2560 * 1920
"""Most pixels a frame may have (4,915,200: 16 times the Duckiebot camera's 640×480, 4× per
side), read from the image's header before it is decoded: decoding allocates what the header
claims, here at most about 15 MB as RGB. Pillow's own bound (``Image.MAX_IMAGE_PIXELS``, about
89 Mpx, 268 MB) is 18 times larger."""
MAX_FRAME_BYTES = 32 * 2**20
"""Largest encoded frame read (bytes; 32 MiB): a camera JPEG of 640×480 is about 50 kB, and even
an uncompressed PNG of :data:`MAX_FRAME_PIXELS` is under 15 MB."""
FRAME_FORMATS = ("JPEG", "PNG")
"""The image formats a frame may come in (the camera publishes JPEG); Pillow tries no other."""

_DECODE_ERRORS = (OSError, ValueError, SyntaxError, EOFError, struct.error)
"""What Pillow's decoders raise for a broken file (truncated data, a bad chunk, ...)."""


def box_average(image: np.ndarray, factor: int) -> np.ndarray:
    """Shrink a uint8 H×W×C image ``factor`` times per axis: each pixel the mean of its
    ``factor`` x ``factor`` block, rounded half up. Integer arithmetic: the same values as
    ``(block.mean(dtype=float32) + 0.5).astype(uint8)``, several times faster. Small factors
    (training's supersampling) add the strided sub-images; large ones (a 640×480 camera
    frame) sum rows in blocks, then columns, about 4× faster there."""
    count = factor * factor
    if factor <= _STRIDED_FACTOR_MAX:
        total = np.full_like(image[::factor, ::factor], count // 2, dtype=np.uint32)
        for i in range(factor):
            for j in range(factor):
                total += image[i::factor, j::factor]
    else:
        rows, columns, channels = image.shape
        row_sums = image.reshape(rows // factor, factor, columns * channels).sum(
            axis=1, dtype=np.uint32)
        total = row_sums.reshape(rows // factor, columns // factor, factor, channels).sum(axis=2)
        total += count // 2
    total //= count
    return total.astype(np.uint8)


def check_frame_bytes(size: int, source: str = "frame") -> None:
    """Refuses an encoded frame of ``size`` bytes over :data:`MAX_FRAME_BYTES`.

    Raises:
        ConfigError: ``<source>: frame: <size> bytes, more than ...``.
    """
    if size > MAX_FRAME_BYTES:
        raise ConfigError(source, "frame", f"{size} bytes, more than the {MAX_FRAME_BYTES} a "
                          "frame may have")


def check_frame_pixels(width: int, height: int, source: str = "frame") -> None:
    """Refuses a frame of ``width`` × ``height`` over :data:`MAX_FRAME_PIXELS`.

    Raises:
        ConfigError: ``<source>: frame: <width>×<height> pixels, more than ...``.
    """
    if width * height > MAX_FRAME_PIXELS:
        raise ConfigError(source, "frame", f"{width}×{height} pixels, more than the "
                          f"{MAX_FRAME_PIXELS} a frame may have")


def decode_image(data: bytes, source: str = "frame") -> np.ndarray:
    """An RGB uint8 H×W×3 array of JPEG or PNG bytes (:data:`FRAME_FORMATS`), refused before
    decoding when the bytes or the pixels its header claims are over the bounds
    (:data:`MAX_FRAME_BYTES`, :data:`MAX_FRAME_PIXELS`).

    Raises:
        ConfigError: ``<source>: frame: <problem>``, one short line.
    """
    check_frame_bytes(len(data), source)
    try:
        # Pillow warns from 89 Mpx and refuses from 179 Mpx as it opens; either is far over
        # the bound checked below, and reported as such
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            image = Image.open(io.BytesIO(data), formats=FRAME_FORMATS)
    except (Image.DecompressionBombWarning, Image.DecompressionBombError):
        raise ConfigError(source, "frame", "its header claims more pixels than the "
                          f"{MAX_FRAME_PIXELS} a frame may have") from None
    except UnidentifiedImageError:
        raise ConfigError(source, "frame", f"not an image ({' or '.join(FRAME_FORMATS)}), "
                          f"{len(data)} bytes") from None
    except _DECODE_ERRORS as err:
        raise ConfigError(source, "frame", f"not an image: {_reason(err)}") from None
    with image:
        check_frame_pixels(*image.size, source)  # the header's size: nothing decoded yet
        try:
            return np.asarray(image.convert("RGB"))
        except _DECODE_ERRORS as err:
            raise ConfigError(source, "frame", f"cannot decode the {image.format} image: "
                              f"{_reason(err)}") from None


def _reason(err: BaseException, limit: int = 200) -> str:
    """``err``'s message on one line, at most ``limit`` characters."""
    return " ".join(str(err).split())[:limit] or type(err).__name__


__all__ = ["FRAME_FORMATS", "MAX_FRAME_BYTES", "MAX_FRAME_PIXELS", "box_average",
           "check_frame_bytes", "check_frame_pixels", "decode_image"]
