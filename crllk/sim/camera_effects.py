"""What a real camera does to its images: JPEG compression and sensor noise (numpy only).

:func:`compress` is baseline JPEG without the entropy coding (which is lossless): colours to
YCbCr, 8x8 block DCT, quantisation with the standard tables scaled by the quality as libjpeg
does, and back. :func:`add_noise` adds Gaussian noise keyed by (seed, frame), so that a frame's
noise is the same however often, and after however many restores, it is drawn.

Both work on a batch of frames at once (:func:`apply_effects`, :func:`compress_frames`,
:func:`add_noise_frames`), each frame with its own quality and noise, giving every frame the
values it gets alone: each transform is one matrix product (one per channel for the vertical
DCT) whose entries are the same sums of the same products, in the same order, as one
frame's.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

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
_TO_YCC32 = _TO_YCC.astype(np.float32)
_FROM_YCC = np.linalg.inv(_TO_YCC).astype(np.float32)
_CHUNK_VALUES = 32_768
"""Most float32 values (128 KiB) in one intermediate array of a batched compression: larger
batches cost more per frame (their arrays leave the CPU caches, and the allocator may fetch
their memory from the system afresh on every call)."""


@functools.lru_cache(maxsize=100)
def quantisation_steps(quality: int) -> np.ndarray:
    """The (3, 8, 8) quantisation steps of Y, Cb and Cr at ``quality`` (1-100), indexed
    (channel, horizontal frequency, vertical frequency): the standard tables (row: vertical
    frequency) scaled as libjpeg scales them."""
    scale = 5000 / quality if quality < 50 else 200 - 2 * quality
    tables = np.stack([_LUMA.T, _CHROMA.T, _CHROMA.T])
    return np.clip(np.floor((tables * scale + 50) / 100), 1, 255).astype(np.float32)


@dataclass(frozen=True)
class FrameEffects:
    """What the camera does to one frame."""

    quality: int
    """JPEG quality (1-100); 0: no compression."""
    noise_std: float
    """Standard deviation of the sensor noise (levels of 255); 0: none."""
    noise_seed: int
    """Key of the episode's noise."""
    frame: int
    """The frame's number in the episode (the noise's other key)."""


def apply_effects(images: np.ndarray, effects: Sequence[FrameEffects | None]) -> np.ndarray:
    """``images`` (uint8, N x H x W x 3) where frame k has ``effects[k]`` (None: unchanged),
    as a new array: compression, then noise, each in one vectorised call over the frames with
    it."""
    compressed = [k for k, e in enumerate(effects) if e is not None and e.quality]
    out = _on_frames(images, compressed, lambda frames: compress_frames(
        frames, [effects[k].quality for k in compressed]))
    noisy = [k for k, e in enumerate(effects) if e is not None and e.noise_std > 0]
    chosen = [effects[k] for k in noisy]
    out = _on_frames(out, noisy, lambda frames: add_noise_frames(
        frames, [e.noise_std for e in chosen], [e.noise_seed for e in chosen],
        [e.frame for e in chosen]))
    return images.copy() if out is images else out


def _on_frames(images: np.ndarray, chosen: list[int],
               transform: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``images`` with the frames ``chosen`` replaced by ``transform`` of them: its result
    when all are chosen, ``images`` itself when none is, else a copy."""
    if not chosen:
        return images
    if len(chosen) == len(images):
        return transform(images)
    out = images.copy()
    out[chosen] = transform(images[chosen])
    return out


def compress(image: np.ndarray, quality: int) -> np.ndarray:
    """A uint8 RGB image (H, W, 3) after JPEG compression at ``quality`` (1-100), without
    chroma subsampling; sizes that are not multiples of 8 are padded by repeating the edge,
    as encoders do."""
    return compress_frames(image[None], [quality])[0]


def compress_frames(images: np.ndarray, qualities: Sequence[int]) -> np.ndarray:
    """:func:`compress` of each frame of ``images`` (uint8, N x H x W x 3) at its quality, a
    few frames per vectorised call (:data:`_CHUNK_VALUES`)."""
    count, height, width, _ = images.shape
    padded_values = 3 * (height + -height % _BLOCK) * (width + -width % _BLOCK)
    chunk = max(1, _CHUNK_VALUES // padded_values)
    if count <= chunk:
        return _compress_chunk(images, tuple(qualities))
    return np.concatenate([_compress_chunk(images[k:k + chunk], tuple(qualities[k:k + chunk]))
                           for k in range(0, count, chunk)])


def _compress_chunk(images: np.ndarray, qualities: tuple[int, ...]) -> np.ndarray:
    """:func:`compress_frames` of a few frames at once. Axes: y, x within a block; br, bc:
    block row and column; n: frame; c: YCbCr channel, k: RGB channel; u, v: horizontal and
    vertical frequency. Every product contracts the first or last axis, so none needs a
    copy."""
    count, height, width, _ = images.shape
    images = _pad_to_blocks(images)
    rows, cols = images.shape[1] // _BLOCK, images.shape[2] // _BLOCK
    pixels = np.empty((_BLOCK, count, rows, cols, _BLOCK, 3), np.float32)  # [y, n, br, bc, x, k]
    np.subtract(images.reshape(count, rows, _BLOCK, cols, _BLOCK, 3), np.float32(128.0),
                out=pixels.transpose(1, 2, 0, 3, 4, 5))
    ycc = _TO_YCC32 @ pixels.reshape(-1, 3).T  # [c, y, n, br, bc, x]
    rows_done = ycc.reshape(-1, _BLOCK) @ _DCT.T  # [c, y, n, br, bc, u]
    coefficients = np.matmul(_DCT, rows_done.reshape(3, _BLOCK, -1))  # [c, v, n, br, bc, u]
    steps = _step_grid(qualities, rows * cols)
    coefficients = coefficients.reshape(steps.shape)
    coefficients /= steps
    np.rint(coefficients, out=coefficients)
    coefficients *= steps
    columns_back = np.matmul(_DCT.T, coefficients.reshape(3, _BLOCK, -1))  # [c, y, .., u]
    blocks = columns_back.reshape(-1, _BLOCK) @ _DCT  # [c, y, n, br, bc, x]
    rgb = blocks.reshape(3, -1).T @ _FROM_YCC.T  # [y, n, br, bc, x, k]
    rgb += 128.5
    np.clip(rgb, 0, 255, out=rgb)
    out = np.empty((count, rows, _BLOCK, cols, _BLOCK, 3), np.uint8)
    out.transpose(2, 0, 1, 3, 4, 5)[...] = rgb.reshape(_BLOCK, count, rows, cols, _BLOCK, 3)
    out = out.reshape(count, rows * _BLOCK, cols * _BLOCK, 3)
    return out if out.shape[1:3] == (height, width) else \
        np.ascontiguousarray(out[:, :height, :width])


def _pad_to_blocks(images: np.ndarray) -> np.ndarray:
    """``images`` (N x H x W x 3) padded to whole blocks by repeating the last row and
    column."""
    for axis in (1, 2):
        if images.shape[axis] % _BLOCK:
            images = images.take(_edge_index(images.shape[axis]), axis=axis)
    return images


@functools.lru_cache(maxsize=8)
def _edge_index(size: int) -> np.ndarray:
    """Indices 0 .. size - 1, then size - 1 again up to a multiple of the block size."""
    return np.minimum(np.arange(size + -size % _BLOCK), size - 1)


@functools.lru_cache(maxsize=16)
def _step_grid(qualities: tuple[int, ...], blocks: int) -> np.ndarray:
    """The quantisation step of every coefficient of ``blocks`` blocks of frames at
    ``qualities``, laid out [c, v, n, block, u] as :func:`_compress_chunk` holds them."""
    steps = np.stack([quantisation_steps(q) for q in qualities])  # (n, c, u, v)
    grid = steps.transpose(1, 3, 0, 2)[:, :, :, None]  # (c, v, n, 1, u)
    return np.ascontiguousarray(np.broadcast_to(grid, (*grid.shape[:3], blocks, _BLOCK)))


NOISE_BANK_FRAMES = 64
"""Frames of standard normal noise drawn once per image size (:func:`noise_bank`)."""
_NOISE_BANK_SEED = 2_025_12_02


@functools.lru_cache(maxsize=8)
def noise_bank(size: int) -> np.ndarray:
    """(NOISE_BANK_FRAMES, size) standard normal values, the same in every process."""
    generator = np.random.default_rng(_NOISE_BANK_SEED)
    return generator.standard_normal((NOISE_BANK_FRAMES, size), dtype=np.float32)


@functools.lru_cache(maxsize=8)
def _doubled_noise_bank(size: int) -> np.ndarray:
    """Each frame of :func:`noise_bank` twice in a row: any rotation is a slice."""
    bank = noise_bank(size)
    return np.concatenate([bank, bank], axis=1)


def add_noise(image: np.ndarray, std: float, seed: int, frame: int) -> np.ndarray:
    """``image`` (uint8) plus Gaussian noise of ``std`` levels, keyed by (``seed``,
    ``frame``): a frame of :func:`noise_bank` rotated by a key-dependent number of pixels
    (64 frames x H·W·3 rotations), several times cheaper than drawing fresh normals; rounded
    and clipped to [0, 255]."""
    return add_noise_frames(image[None], [std], [seed], [frame])[0]


def add_noise_frames(images: np.ndarray, stds: Sequence[float], seeds: Sequence[int],
                     frames: Sequence[int]) -> np.ndarray:
    """:func:`add_noise` of each frame of ``images`` (uint8, N x ...) with its own standard
    deviation (a Python float, applied in float32) and key."""
    size = images[0].size
    bank = _doubled_noise_bank(size)
    noise = np.empty(images.shape, np.float32)
    for row, std, seed, frame in zip(noise.reshape(len(images), size), stds, seeds, frames,
                                     strict=True):
        key = (seed * 0x9E3779B1 + frame * 0x85EBCA6B) & 0xFFFFFFFF
        shift = (key >> 8) % size
        np.multiply(bank[key % NOISE_BANK_FRAMES, shift:shift + size], np.float32(std), out=row)
    noise += images
    noise += np.float32(0.5)
    return np.clip(noise, 0, 255, out=noise).astype(np.uint8)
