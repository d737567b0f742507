"""Image arithmetic shared by the simulator's renders and the robot's camera frames (numpy
only, so that the pilot on a robot needs nothing heavier)."""

from __future__ import annotations

import numpy as np

_STRIDED_FACTOR_MAX = 4
"""Largest factor :func:`box_average` sums as strided sub-images (faster up to here)."""


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


__all__ = ["box_average"]
