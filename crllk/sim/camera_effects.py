"""What a real camera does to its images: JPEG compression and sensor noise (numpy only).

:func:`compress` is baseline JPEG without the entropy coding (which is lossless): colours to
YCbCr, 8x8 block DCT, quantisation with the standard tables scaled by the quality as libjpeg
does, and back. :func:`add_noise` adds Gaussian noise keyed by (seed, frame), so that a frame's
noise is the same however often, and after however many restores, it is drawn.
"""

from __future__ import annotations

import functools
import math

import numpy as np

_BLOCK = 8
"""JPEG block size (pixels)."""
_LUMA = np.array([
    [16, 11, 10, 16, 24, 40, 51, 61], [12, 12, 14, 19, 26, 58, 60, 55],
    [14, 13, 16, 24, 40, 57, 69, 56], [14, 17, 22, 29, 51, 87, 80, 62],
    [18, 22, 37, 56, 68, 109, 103, 77], [24, 35, 55, 64, 81, 104, 113, 92],
    [49, 64, 78, 87, 103, 121, 120, 101], [72, 92, 95, 98, 112, 100, 103, 99]], np.float32)
"""The JPEG standard's luminance quantisation table (quality 50)."""
_CHROMA = np.full((8, 8), 99, np.float32)
_CHROMA[:4, :4] = [[17, 18, 24, 47], [18, 21, 26, 66], [24, 26, 56, 99], [47, 66, 99, 99]]
"""The JPEG standard's chrominance quantisation table (quality 50)."""
_TO_YCC = np.array([[0.299, 0.587, 0.114], [-0.168736, -0.331264, 0.5],
                    [0.5, -0.418688, -0.081312]])
"""RGB to YCbCr (JFIF)."""


def _dct_matrix() -> np.ndarray:
    """The orthonormal 8-point DCT-II matrix."""
    k = np.arange(_BLOCK)[:, None]
    n = np.arange(_BLOCK)[None, :]
    matrix = np.cos(math.pi * (2 * n + 1) * k / (2 * _BLOCK)) * math.sqrt(2 / _BLOCK)
    matrix[0] /= math.sqrt(2)
    return matrix


_DCT = _dct_matrix().astype(np.float32)
_FROM_YCC = np.linalg.inv(_TO_YCC).astype(np.float32)


@functools.lru_cache(maxsize=100)
def quantisation_steps(quality: int) -> np.ndarray:
    """The (3, 8, 8) quantisation steps of Y, Cb and Cr at ``quality`` (1-100), indexed
    (channel, horizontal frequency, vertical frequency): the standard tables (row: vertical
    frequency) scaled as libjpeg scales them."""
    scale = 5000 / quality if quality < 50 else 200 - 2 * quality
    tables = np.stack([_LUMA.T, _CHROMA.T, _CHROMA.T])
    return np.clip(np.floor((tables * scale + 50) / 100), 1, 255).astype(np.float32)


def _along_last(array: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """``array @ matrix`` as one 2-D matrix product (not one small product per block)."""
    return (array.reshape(-1, array.shape[-1]) @ matrix).reshape(*array.shape[:-1], -1)


def compress(image: np.ndarray, quality: int) -> np.ndarray:
    """A uint8 RGB image (H, W, 3) after JPEG compression at ``quality`` (1-100), without
    chroma subsampling; sizes that are not multiples of 8 are padded by repeating the edge,
    as encoders do."""
    height, width, _ = image.shape
    pad_h, pad_w = -height % _BLOCK, -width % _BLOCK
    if pad_h:
        image = np.concatenate([image, np.repeat(image[-1:], pad_h, axis=0)], axis=0)
    if pad_w:
        image = np.concatenate([image, np.repeat(image[:, -1:], pad_w, axis=1)], axis=1)
    rows, cols = image.shape[0] // _BLOCK, image.shape[1] // _BLOCK
    pixels = image.astype(np.float32)
    pixels -= 128.0
    ycc = _along_last(pixels, _TO_YCC.T.astype(np.float32))  # (y, x, channel)
    # (block row, block column, channel, y, x)
    blocks = ycc.reshape(rows, _BLOCK, cols, _BLOCK, 3).transpose(0, 2, 4, 1, 3)
    rows_done = _along_last(blocks, _DCT.T)  # (.., y, horizontal frequency)
    coefficients = _along_last(rows_done.swapaxes(-1, -2), _DCT.T)  # (.., u, v)
    steps = quantisation_steps(quality)
    coefficients /= steps
    np.round(coefficients, out=coefficients)
    coefficients *= steps
    columns_back = _along_last(coefficients, _DCT)  # (.., u, y)
    blocks = _along_last(columns_back.swapaxes(-1, -2), _DCT)  # (.., y, x)
    ycc = blocks.transpose(0, 3, 1, 4, 2).reshape(rows * _BLOCK, cols * _BLOCK, 3)
    rgb = _along_last(ycc[:height, :width], _FROM_YCC.T)
    rgb += 128.5
    return np.clip(rgb, 0, 255, out=rgb).astype(np.uint8)


NOISE_BANK_FRAMES = 64
"""Frames of standard normal noise drawn once per image size (:func:`noise_bank`)."""
_NOISE_BANK_SEED = 2_025_12_02


@functools.lru_cache(maxsize=8)
def noise_bank(size: int) -> np.ndarray:
    """(NOISE_BANK_FRAMES, size) standard normal values, the same in every process."""
    generator = np.random.default_rng(_NOISE_BANK_SEED)
    return generator.standard_normal((NOISE_BANK_FRAMES, size), dtype=np.float32)


def add_noise(image: np.ndarray, std: float, seed: int, frame: int) -> np.ndarray:
    """``image`` (uint8) plus Gaussian noise of ``std`` levels, keyed by (``seed``,
    ``frame``): a frame of :func:`noise_bank` rotated by a key-dependent number of pixels
    (64 frames x H·W·3 rotations), several times cheaper than drawing fresh normals; rounded
    and clipped to [0, 255]."""
    flat = image.reshape(-1)
    key = (seed * 0x9E3779B1 + frame * 0x85EBCA6B) & 0xFFFFFFFF
    row = noise_bank(flat.size)[key % NOISE_BANK_FRAMES]
    shift = (key >> 8) % flat.size
    noise = np.concatenate((row[shift:], row[:shift]))
    noise *= std
    noise += flat
    noise += 0.5
    return np.clip(noise, 0, 255, out=noise).astype(np.uint8).reshape(image.shape)
