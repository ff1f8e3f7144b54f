"""Moving images between the layouts of the project and of its networks, as numba kernels.

Images are (H, W, C), channels last (docs/conventions.md); the ONNX networks take and give (C, H, W). On a
512² frame numpy's joining and transposing copies of TAAU's 7-channel history and the network's output (strided
reads, one thread) cost 7-10 ms around a ~20 ms network; here each is one parallel pass over rows, 1.6-2.1 ms
together (``benchmarks/bench_layout.py``). The images may be strided views (a window of a frame's buffers, a feature
of its packed array): each kernel reads them in place, no contiguous copy first.
"""
from __future__ import annotations

from typing import Sequence

import numba
import numpy as np


@numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
def _to_channels_first(image: np.ndarray, out: np.ndarray, first: int) -> None:
    height, width, channels = image.shape
    for y in numba.prange(height):
        for c in range(channels):
            row = out[first + c, y]
            for x in range(width):
                row[x] = image[y, x, c]


@numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
def _to_image_clipped(planes: np.ndarray, out: np.ndarray) -> None:
    channels, height, width = planes.shape
    for y in numba.prange(height):
        for c in range(channels):
            row = planes[c, y]
            for x in range(width):
                out[y, x, c] = min(max(row[x], np.float32(0.0)), np.float32(1.0))


def to_channels_first(images: Sequence[np.ndarray], out: np.ndarray | None = None) -> np.ndarray:
    """``images``, each (H, W, c) and strided as they come, as one contiguous (C, H, W) float32 array holding their
    channels one after the other (what ``np.concatenate(images, -1).transpose(2, 0, 1)`` holds, without the joined
    copy), written into ``out`` when given (a buffer kept between frames: fresh multi-MB arrays cost page faults)."""
    images = [np.asarray(image, dtype=np.float32) for image in images]
    height, width = images[0].shape[:2]
    shape = (sum(image.shape[2] for image in images), height, width)
    if any(image.shape[:2] != (height, width) for image in images):
        raise ValueError(f"images of different sizes: {[image.shape for image in images]}")
    if out is None:
        out = np.empty(shape, np.float32)
    elif out.shape != shape or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a contiguous float32 array of shape {shape}, got {out.dtype} {out.shape}")
    first = 0
    for image in images:
        _to_channels_first(image, out, first)
        first += image.shape[2]
    return out


def to_image_clipped(planes: np.ndarray) -> np.ndarray:
    """``planes`` (C, H, W) as a new (H, W, C) float32 image clipped to [0, 1] (what a network's output becomes
    before anyone sees it)."""
    planes = np.ascontiguousarray(planes, dtype=np.float32)
    out = np.empty(planes.shape[1:] + planes.shape[:1], np.float32)
    _to_image_clipped(planes, out)
    return out


@numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
def _clip_with_window(image: np.ndarray, planes: np.ndarray, top: int, left: int, where: np.ndarray,
                      scale: int) -> None:
    height, width, channels = image.shape
    rows, columns = planes.shape[1], planes.shape[2]
    low, high = np.float32(0.0), np.float32(1.0)
    for y in numba.prange(height):
        inside = top <= y < top + rows
        taken = where[(y - top) // scale] if inside else where[0]
        for x in range(width):
            if inside and left <= x < left + columns and taken[(x - left) // scale]:
                for c in range(channels):
                    image[y, x, c] = min(max(planes[c, y - top, x - left], low), high)
            else:
                for c in range(channels):
                    image[y, x, c] = min(max(image[y, x, c], low), high)


def clip_with_window(image: np.ndarray, planes: np.ndarray, top: int = 0, left: int = 0,
                     where: np.ndarray | None = None, scale: int = 1) -> np.ndarray:
    """``image`` (H, W, C) float32, in place and returned: ``planes`` (C, h, w) over its window of rows ``top`` ..
    ``top`` + h - 1 and columns ``left`` .. ``left`` + w - 1, the rest its own, all clipped to [0, 1]; one parallel
    pass (what a network's output on a window of the image it refines becomes before anyone sees it). ``where``
    (h / ``scale``, w / ``scale``, bool: per block of ``scale`` x ``scale`` pixels of the window, an LR pixel of a
    network that upscales by ``scale``) takes the planes only in its True blocks, the image's own pixels elsewhere;
    None takes them everywhere in the window."""
    height, width, channels = image.shape
    if planes.shape[0] != channels or not (0 <= top <= top + planes.shape[1] <= height
                                           and 0 <= left <= left + planes.shape[2] <= width):
        raise ValueError(f"planes {planes.shape} at ({top}, {left}) do not lie in an image of shape {image.shape}")
    blocks = (-(-planes.shape[1] // scale), -(-planes.shape[2] // scale))
    if where is None:
        where = np.ones(blocks, np.bool_)
    elif where.shape != blocks:
        raise ValueError(f"where must hold one flag per {scale}x{scale} block of the planes {planes.shape}: "
                         f"shape {blocks}, got {where.shape}")
    _clip_with_window(image, np.asarray(planes, dtype=np.float32), int(top), int(left),
                      np.ascontiguousarray(where, dtype=np.bool_).reshape(max(blocks[0], 1), -1), int(scale))
    return image
