"""Backward warping with motion vectors (docs/conventions.md).

A motion vector (dx, dy) at pixel (x, y) points, in pixels, to where the same surface point was
in the previous frame, so ``warped[y, x] = prev[y + dy, x + dx]`` (bilinear between pixel
centres).
"""
from __future__ import annotations

import numpy as np


def backward_warp(previous: np.ndarray, motion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Warp ``previous`` (H, W[, C]) to the current frame with ``motion`` (H, W, 2).

    Returns (warped, valid): ``valid`` is False where the reprojected position falls outside
    the previous image (those pixels take the clamped edge value).
    """
    h, w = motion.shape[:2]
    if previous.shape[:2] != (h, w):
        raise ValueError(f"image {previous.shape[:2]} and motion {motion.shape[:2]} sizes differ")
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    sx = xs + motion[..., 0]
    sy = ys + motion[..., 1]
    valid = (sx > -0.5) & (sx < w - 0.5) & (sy > -0.5) & (sy < h - 0.5)
    sx = np.clip(sx, 0.0, w - 1.0)
    sy = np.clip(sy, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(sx).astype(np.int64), w - 2) if w > 1 else np.zeros_like(sx, dtype=np.int64)
    y0 = np.minimum(np.floor(sy).astype(np.int64), h - 2) if h > 1 else np.zeros_like(sy, dtype=np.int64)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = sx - x0, sy - y0
    if previous.ndim == 3:
        fx, fy = fx[..., None], fy[..., None]
    top = previous[y0, x0] * (1 - fx) + previous[y0, x1] * fx
    bottom = previous[y1, x0] * (1 - fx) + previous[y1, x1] * fx
    return (top * (1 - fy) + bottom * fy).astype(previous.dtype, copy=False), valid
