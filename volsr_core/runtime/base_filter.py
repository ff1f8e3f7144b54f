"""The learned base filter of variant XS on the CPU: numba kernels on (H, W, 3) images.

A VolSR model whose network is only its base filter (:class:`~volsr_core.sr.network.BaseFilter`,
variant XS) is one depthwise k x k convolution of the base clipped to [0, 1], edge pixels repeated
past the border. :func:`filter_image` does it on images laid out as TAAU makes them, so the
upscaler needs no network inputs and no transposes for it: one pass lays the clipped, padded
channels apart, a second sums each tap over whole rows (the loops vectorise) and interleaves the
result. 1.0 ms for a 5x5 filter and 2.8 ms for a 9x9 one on a 512² frame (2 cores), where
onnxruntime's depthwise Conv takes 2.4 and 10.8 ms without its transposes. The weights travel in
the ONNX file's metadata (:data:`FILTER_KEY`, written by :func:`~volsr_core.runtime.export.
export_onnx`); the graph stays the reference the kernel is tested against.
"""
from __future__ import annotations

import json
from pathlib import Path

import numba
import numpy as np

from volsr_core.errors import InputError

FILTER_KEY = "volsr.base_filter"  # ONNX metadata: {"weights": (3, k, k) nested lists, "bias": 3 numbers}


@numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
def _padded_planes(image: np.ndarray, r: int) -> np.ndarray:
    """(C, H + 2r, W + 2r): ``image`` (H, W, C) clipped to [0, 1], channels apart, edge pixels repeated."""
    height, width, channels = image.shape
    planes = np.empty((channels, height + 2 * r, width + 2 * r), np.float32)
    for y in numba.prange(height + 2 * r):
        sy = min(max(y - r, 0), height - 1)
        for x in range(width + 2 * r):
            sx = min(max(x - r, 0), width - 1)
            for c in range(channels):
                planes[c, y, x] = min(max(image[sy, sx, c], np.float32(0.0)), np.float32(1.0))
    return planes


@numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
def _filter_rows(planes: np.ndarray, weights: np.ndarray, bias: np.ndarray, out: np.ndarray) -> None:
    """``out`` (H, W, C) from ``planes`` (:func:`_padded_planes`), a row at a time: each tap's loop over
    the row into a per-channel accumulator (it vectorises), the accumulators interleaved into ``out``."""
    height, width, channels = out.shape
    k = weights.shape[1]
    for y in numba.prange(height):
        accumulator = np.empty((channels, width), np.float32)
        for c in range(channels):
            row = accumulator[c]
            row[:] = bias[c]
            for dy in range(k):
                source = planes[c, y + dy]
                for dx in range(k):
                    weight = weights[c, dy, dx]
                    for x in range(width):
                        row[x] += weight * source[x + dx]
        for x in range(width):
            for c in range(channels):
                out[y, x, c] = accumulator[c, x]


def filter_image(image: np.ndarray, weights: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C), clipped to [0, 1] and edge-padded, through ``weights`` (C, k, k) and ``bias``
    (C,): a new (H, W, C) float32 image, what the network's BaseFilter computes (channels first there)."""
    planes = _padded_planes(np.ascontiguousarray(image, dtype=np.float32), weights.shape[1] // 2)
    out = np.empty(image.shape, np.float32)
    _filter_rows(planes, np.ascontiguousarray(weights, dtype=np.float32), np.asarray(bias, dtype=np.float32), out)
    return out


def filter_metadata(weights: np.ndarray, bias: np.ndarray) -> str:
    """The :data:`FILTER_KEY` metadata value for ``weights`` (3, k, k) and ``bias`` (3,)."""
    return json.dumps({"weights": np.asarray(weights, dtype=float).tolist(), "bias": np.asarray(bias, dtype=float).tolist()})


def read_filter_metadata(text: str, path: Path, kernel: int) -> tuple[np.ndarray, np.ndarray]:
    """``(weights (3, kernel, kernel), bias (3,))`` float32 from a :data:`FILTER_KEY` value; a one-line
    InputError naming ``path`` when it is not that."""
    try:
        mapping = json.loads(text)
        weights = np.asarray(mapping["weights"], dtype=np.float32)
        bias = np.asarray(mapping["bias"], dtype=np.float32)
    except (ValueError, KeyError, TypeError) as err:
        raise InputError(path, f"{FILTER_KEY}: not the filter's weights and bias ({err})") from None
    if weights.shape != (3, kernel, kernel) or bias.shape != (3,) or not (np.isfinite(weights).all()
                                                                          and np.isfinite(bias).all()):
        raise InputError(path, f"{FILTER_KEY}: expected finite weights of shape (3, {kernel}, {kernel}) and 3 "
                         f"biases, got {weights.shape} and {bias.shape}")
    return weights, bias
