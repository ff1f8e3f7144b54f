"""The learned base filter of variant XS on the CPU: numba kernels on (H, W, 3) images.

A VolSR model whose network is only its base filter (:class:`~volsr_core.sr.network.BaseFilter`,
variant XS) is one depthwise k x k convolution of the base clipped to [0, 1], edge pixels repeated
past the border, or a pair of them, each pixel taking the one its local orientation picks
(:func:`~volsr_core.sr.network.second_orientation`, the same stages here). :func:`filter_image` does it
on images laid out as TAAU makes them, so the upscaler needs no network inputs and no transposes for
it: one pass lays the clipped, padded channels apart, a second sums each pixel's taps row by row (the
tap count compiled in, so the taps unroll and the pixels vectorise; a pair sums both filters in the same
pass and blends) and interleaves the result; work buffers stay in a :class:`Scratch` between frames. On
TAAU's 512² estimates (2 cores, medians, ``benchmarks/bench_base_filter.py``): 1.6 ms for the 5x5 pair of XS
2x and for a 9x9 filter (XS 4x's until 2026-11-25, now 5x5: 1.1 ms; docs/network.md), where onnxruntime's
depthwise Conv took 2.4 (5x5) and 10.8 ms (9x9), on a faster machine, without its transposes. The weights
travel in the ONNX file's metadata (:data:`FILTER_KEY`, written by
:func:`~volsr_core.runtime.export.export_onnx`); the graph stays the reference the kernel is tested against.
"""
from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Callable

import numba
import numpy as np

from volsr_core.errors import InputError
from volsr_core.sr.network_config import ORIENTATION_LUMA, ORIENTATION_SMOOTHING

FILTER_KEY = "volsr.base_filter"  # ONNX metadata: {"weights": (3, k, k) or (2, 3, k, k) nested lists, "bias": 3 or 2x3}
LUMA = np.asarray(ORIENTATION_LUMA, dtype=np.float32)
SMOOTHING = np.asarray(ORIENTATION_SMOOTHING, dtype=np.float32)


class Scratch:
    """Work buffers :func:`filter_image` keeps between calls on frames of one size: fresh multi-MB arrays
    every frame cost page faults (about as much as the filter itself at 512²). One per caller (not shared
    between threads)."""

    def __init__(self) -> None:
        self._buffers: dict[str, np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: type = np.float32) -> np.ndarray:
        """The buffer ``name`` of ``shape`` (contents undefined), made anew only when the shape changes."""
        buffer = self._buffers.get(name)
        if buffer is None or buffer.shape != shape:
            buffer = self._buffers[name] = np.empty(shape, dtype)
        return buffer


@numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
def _padded_planes(image: np.ndarray, r: int, planes: np.ndarray) -> None:
    """``planes`` (C, H + 2r, W + 2r) from ``image`` (H, W, C): clipped to [0, 1], channels apart, edge
    pixels repeated."""
    height, width, channels = image.shape
    for y in numba.prange(height + 2 * r):
        sy = min(max(y - r, 0), height - 1)
        for x in range(width + 2 * r):
            sx = min(max(x - r, 0), width - 1)
            for c in range(channels):
                planes[c, y, x] = min(max(image[sy, sx, c], np.float32(0.0)), np.float32(1.0))


@numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
def _second_orientation(planes: np.ndarray, pad: int, luma_weights: np.ndarray, taps: np.ndarray,
                        luma: np.ndarray, across: np.ndarray, second: np.ndarray) -> None:
    """``second`` (H, W) uint8, 1 where a filter pair uses its second filter, from ``planes``
    (:func:`_padded_planes` with ``pad`` >= 1; ``luma`` and ``across`` are work buffers of the padded and
    the image's size): the stages of :func:`~volsr_core.sr.network.second_orientation` (luma of the clipped
    image, central differences, their product smoothed along x, then y, edge pixels repeated at each step,
    negative), laid out so that the inner loops need no index clamps (they vectorise)."""
    channels, padded_height, padded_width = planes.shape
    height, width = padded_height - 2 * pad, padded_width - 2 * pad
    r = taps.shape[0] // 2
    for y in numba.prange(padded_height):
        row = luma[y]
        row[:] = luma_weights[0] * planes[0, y]
        for c in range(1, channels):
            weight, source = luma_weights[c], planes[c, y]
            for x in range(padded_width):
                row[x] += weight * source[x]
    for y in numba.prange(height):
        here, up, down = luma[y + pad], luma[y + pad - 1], luma[y + pad + 1]
        product = np.empty(width + 2 * r, np.float32)  # r repeated edge values each side
        for x in range(width):
            product[x + r] = (np.float32(0.5) * (here[x + pad + 1] - here[x + pad - 1]) * np.float32(0.5)
                              * (down[x + pad] - up[x + pad]))
        for i in range(r):
            product[i], product[width + r + i] = product[r], product[width + r - 1]
        out = across[y]
        out[:] = np.float32(0.0)
        for i in range(taps.shape[0]):
            tap = taps[i]
            for x in range(width):
                out[x] += tap * product[x + i]
    for y in numba.prange(height):
        smoothed = np.zeros(width, np.float32)
        for i in range(taps.shape[0]):
            tap, source = taps[i], across[min(max(y + i - r, 0), height - 1)]
            for x in range(width):
                smoothed[x] += tap * source[x]
        for x in range(width):
            second[y, x] = smoothed[x] < 0


_FLOAT32_MAX = np.finfo(np.float32).max


@functools.lru_cache(maxsize=None)
def _filter_rows(taps: int) -> Callable:
    """The kernel for one filter of ``taps`` x ``taps`` (compiled once per size, cached on disk):
    ``rows(planes, weights, bias, low, high, out)`` fills ``out`` (H, W, C) from ``planes`` (:func:`_padded_planes`)
    through ``weights`` (1, C, k, k) and ``bias`` (1, C), a row and a channel at a time: per tap row, each pixel's
    ``taps`` products summed in registers into a row accumulator (the tap count a compile-time constant, so the
    taps unroll and the pixels vectorise: 1.7 times as fast at 9 taps as a pass per tap over the row), then
    clamped to [``low``, ``high``] and interleaved into ``out``."""

    @numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
    def rows(planes, weights, bias, low, high, out):
        height, width, channels = out.shape
        for y in numba.prange(height):
            total = np.empty(width, np.float32)
            for c in range(channels):
                total[:] = bias[0, c]
                for dy in range(taps):
                    source = planes[c, y + dy]
                    row = weights[0, c, dy]
                    for x in range(width):
                        value = total[x]
                        for dx in range(taps):
                            value += row[dx] * source[x + dx]
                        total[x] = value
                for x in range(width):
                    out[y, x, c] = min(max(total[x], low), high)

    return rows


@functools.lru_cache(maxsize=None)
def _filter_rows_pair(taps: int) -> Callable:
    """:func:`_filter_rows` for a pair (``rows(planes, weights, bias, second, low, high, out)``, ``weights``
    (2, C, k, k), ``bias`` (2, C)): both filters summed in the same pass (one load, two products), then each pixel
    takes filter ``second[y, x]`` by a blend with weight 0 or 1 (no branch, so it vectorises too)."""

    @numba.njit(parallel=True, fastmath=True, error_model="numpy", boundscheck=False, cache=True)
    def rows(planes, weights, bias, second, low, high, out):
        height, width, channels = out.shape
        for y in numba.prange(height):
            first = np.empty(width, np.float32)
            other = np.empty(width, np.float32)
            pick = np.empty(width, np.float32)
            for x in range(width):
                pick[x] = second[y, x]
            for c in range(channels):
                first[:] = bias[0, c]
                other[:] = bias[1, c]
                for dy in range(taps):
                    source = planes[c, y + dy]
                    row, row_other = weights[0, c, dy], weights[1, c, dy]
                    for x in range(width):
                        value, value_other = first[x], other[x]
                        for dx in range(taps):
                            tap = source[x + dx]
                            value += row[dx] * tap
                            value_other += row_other[dx] * tap
                        first[x], other[x] = value, value_other
                for x in range(width):
                    out[y, x, c] = min(max(first[x] + pick[x] * (other[x] - first[x]), low), high)

    return rows


def filter_image(image: np.ndarray, weights: np.ndarray, bias: np.ndarray,
                 scratch: Scratch | None = None, clip_output: bool = False) -> np.ndarray:
    """``image`` (H, W, 3), clipped to [0, 1] and edge-padded, through ``weights`` (n, 3, k, k) and ``bias``
    (n, 3), n = 1 or a pair chosen per pixel by orientation: a new (H, W, 3) float32 image, what the network's
    :class:`~volsr_core.sr.network.BaseFilter` computes (channels first there). ``scratch`` keeps the work
    buffers for the next call (a fresh set each call without it); ``clip_output`` clips the result to [0, 1] in
    the same pass (what a displayed frame needs, without a second pass over it)."""
    scratch = Scratch() if scratch is None else scratch
    image = np.ascontiguousarray(image, dtype=np.float32)
    weights = np.ascontiguousarray(weights, dtype=np.float32)
    height, width = image.shape[:2]
    pad = weights.shape[2] // 2
    planes = scratch.get("planes", (3, height + 2 * pad, width + 2 * pad))
    _padded_planes(image, pad, planes)
    bias = np.asarray(bias, dtype=np.float32)
    out = np.empty(image.shape, np.float32)
    # the kernels clamp as they write ``out``; unclipped, to finite bounds (their fastmath assumes no infinities)
    low, high = (np.float32(0.0), np.float32(1.0)) if clip_output else (-_FLOAT32_MAX, _FLOAT32_MAX)
    if weights.shape[0] > 1:
        second = scratch.get("second", (height, width), np.uint8)
        _second_orientation(planes, pad, LUMA, SMOOTHING, scratch.get("luma", planes.shape[1:]),
                            scratch.get("across", (height, width)), second)
        _filter_rows_pair(weights.shape[2])(planes, weights, bias, second, low, high, out)
    else:
        _filter_rows(weights.shape[2])(planes, weights, bias, low, high, out)
    return out


def filter_metadata(weights: np.ndarray, bias: np.ndarray) -> str:
    """The :data:`FILTER_KEY` metadata value for ``weights`` (n, 3, k, k) and ``bias`` (n, 3); one filter is
    written (3, k, k) and (3,), as models made before filter pairs hold it."""
    weights, bias = np.asarray(weights, dtype=float), np.asarray(bias, dtype=float)
    if weights.shape[0] == 1:
        weights, bias = weights[0], bias[0]
    return json.dumps({"weights": weights.tolist(), "bias": bias.tolist()})


def read_filter_metadata(text: str, path: Path, kernel: int, orientations: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """``(weights (orientations, 3, kernel, kernel), bias (orientations, 3))`` float32 from a
    :data:`FILTER_KEY` value; a one-line InputError naming ``path`` when it is not that."""
    try:
        mapping = json.loads(text)
        weights = np.asarray(mapping["weights"], dtype=np.float32)
        bias = np.asarray(mapping["bias"], dtype=np.float32)
    except (ValueError, KeyError, TypeError) as err:
        raise InputError(path, f"{FILTER_KEY}: not the filter's weights and bias ({err})") from None
    expected = (3, kernel, kernel) if orientations == 1 else (orientations, 3, kernel, kernel)
    if weights.shape != expected or bias.shape != expected[:-2] or not (np.isfinite(weights).all()
                                                                        and np.isfinite(bias).all()):
        raise InputError(path, f"{FILTER_KEY}: expected finite weights of shape {expected} and biases of shape "
                         f"{expected[:-2]}, got {weights.shape} and {bias.shape}")
    return weights.reshape(orientations, 3, kernel, kernel), bias.reshape(orientations, 3)
