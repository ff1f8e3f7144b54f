"""Variant XS's base filter as CUDA kernels (numba-cuda), on device arrays: what :func:`~volsr_core.runtime.
base_filter.filter_image` does on the CPU, one thread per pixel, so a TAAU estimate made on the GPU is filtered
there and only the (H, W, 3) result needs to leave the device.

The same sums in the same order as the CPU kernels (which lay the image out in padded planes first so that their
rows vectorise; here each thread reads its taps with the indices clamped to the image instead): the input clipped
to [0, 1], edge pixels repeated past the border; for a filter pair the orientation test of
:func:`~volsr_core.sr.network.second_orientation` (luma, central differences, their product smoothed along x then
y, negative picks the second filter) in the same launch: each block makes its tiles of luma, product and smoothed
product in shared memory first, in named stages. Each launch costs the host about 0.1 ms on the lent H200, so the
filter is one (docs/performance-gpu.md, "Seventh lease"). Tested
against the CPU kernels in Numba's CUDA simulator (``tests/test_temporal_cuda.py``). Importing this module needs
``numba.cuda``.
"""
from __future__ import annotations

import functools

import numpy as np

if not hasattr(np, "row_stack"):  # NumPy >= 2.5 removed it; numba-cuda <= 0.30 still overloads it at import
    np.row_stack = np.vstack

from numba import cuda, float32  # noqa: E402

from volsr_core.runtime.base_filter import _FLOAT32_MAX, LUMA, SMOOTHING  # noqa: E402

THREADS = (16, 8)  # (x, y): a block's pixels; the filter pair's tiles below are sized to it
_RADIUS = SMOOTHING.shape[0] // 2  # the orientation smoothing's radius, along x and along y
# a filter pair's block keeps in shared memory the smoothed product for its rows and the smoothing's halo along y,
# the gradient product for those and the halo along x, and the luma for those and the central differences' halo
_ACROSS_TILE = (THREADS[1] + 2 * _RADIUS, THREADS[0])
_PRODUCT_TILE = (THREADS[1] + 2 * _RADIUS, THREADS[0] + 2 * _RADIUS)
_LUMA_TILE = (THREADS[1] + 2 * _RADIUS + 2, THREADS[0] + 2 * _RADIUS + 2)
_BLOCK = THREADS[0] * THREADS[1]


def _blocks(width: int, height: int) -> tuple[int, int]:
    return (width + THREADS[0] - 1) // THREADS[0], (height + THREADS[1] - 1) // THREADS[1]


@cuda.jit(device=True, inline=True)
def _clamped(index, size):
    """``index`` clamped to [0, size): edge pixels repeated past the border."""
    return min(max(index, 0), size - 1)


@cuda.jit(device=True, inline=True)
def _unit(value):
    """``value`` clipped to [0, 1], as the filter's input is."""
    return min(max(value, float32(0.0)), float32(1.0))


@cuda.jit(device=True, inline=True)
def _luma_stage(image, luma_weights, y0, x0, luma):
    """The block's share of ``luma`` (``_LUMA_TILE``): entry (j, i) the luma (the weighted sum of the clipped
    channels) at image pixel (y0 - r - 1 + j, x0 - r - 1 + i) clamped to the image, r the smoothing's radius."""
    height, width = image.shape[0], image.shape[1]
    for entry in range(cuda.threadIdx.y * THREADS[0] + cuda.threadIdx.x, _LUMA_TILE[0] * _LUMA_TILE[1], _BLOCK):
        j, i = entry // _LUMA_TILE[1], entry % _LUMA_TILE[1]
        y, x = _clamped(y0 - _RADIUS - 1 + j, height), _clamped(x0 - _RADIUS - 1 + i, width)
        value = luma_weights[0] * _unit(image[y, x, 0])
        for c in range(1, image.shape[2]):
            value += luma_weights[c] * _unit(image[y, x, c])
        luma[j, i] = value


@cuda.jit(device=True, inline=True)
def _product_stage(height, width, y0, x0, luma, product):
    """The block's share of ``product`` (``_PRODUCT_TILE``): entry (j, i) the product of the luma's central
    differences along x and y at image pixel (y0 - r + j, x0 - r + i) clamped to the image, read from ``luma``
    (whose entries past the border hold the edge's values, so a clamped pixel's neighbours are its own)."""
    for entry in range(cuda.threadIdx.y * THREADS[0] + cuda.threadIdx.x, _PRODUCT_TILE[0] * _PRODUCT_TILE[1],
                       _BLOCK):
        j, i = entry // _PRODUCT_TILE[1], entry % _PRODUCT_TILE[1]
        # the clamped pixel's place in the luma tile
        row = _clamped(y0 - _RADIUS + j, height) - (y0 - _RADIUS - 1)
        col = _clamped(x0 - _RADIUS + i, width) - (x0 - _RADIUS - 1)
        across = float32(0.5) * (luma[row, col + 1] - luma[row, col - 1])
        down = float32(0.5) * (luma[row + 1, col] - luma[row - 1, col])
        product[j, i] = across * down


@cuda.jit(device=True, inline=True)
def _across_stage(smoothing, product, across):
    """The block's share of ``across`` (``_ACROSS_TILE``): ``product`` smoothed along x by ``smoothing``."""
    for entry in range(cuda.threadIdx.y * THREADS[0] + cuda.threadIdx.x, _ACROSS_TILE[0] * _ACROSS_TILE[1], _BLOCK):
        j, i = entry // _ACROSS_TILE[1], entry % _ACROSS_TILE[1]
        value = float32(0.0)
        for k in range(smoothing.shape[0]):
            value += smoothing[k] * product[j, i + k]
        across[j, i] = value


@cuda.jit(device=True, inline=True)
def _second_picked(smoothing, across):
    """1.0 where ``across`` smoothed along y by ``smoothing`` is negative at this thread's pixel, else 0.0."""
    value = float32(0.0)
    for k in range(smoothing.shape[0]):
        value += smoothing[k] * across[cuda.threadIdx.y + k, cuda.threadIdx.x]
    return float32(1.0) if value < 0 else float32(0.0)


@functools.cache
def _filter_pixel(taps: int, pair: bool):
    """The device function that writes ``out[y, x]`` (H, W, 3) for a k x k filter (k = ``taps``), or a ``pair``:
    per channel the bias plus the taps of the clipped, edge-repeated image through ``weights``, the flat (n, 3, k, k)
    array (n = 2 for a pair), ``bias`` the flat (n, 3); for a pair, blended into filter 1 by ``pick`` (0 or 1: both
    summed, then blended, as the CPU kernel), clamped to [``low``, ``high``]. The taps and the pair are compile-time
    constants, so the loops unroll and each weight's index is a constant."""
    pad, second = taps // 2, 3 * taps * taps

    @cuda.jit(device=True, inline=True)
    def write(image, weights, bias, pick, low, high, out, y, x):
        height, width = image.shape[0], image.shape[1]
        first_r, first_g, first_b = bias[0], bias[1], bias[2]
        other_r = other_g = other_b = float32(0.0)
        if pair:
            other_r, other_g, other_b = bias[3], bias[4], bias[5]
        for dy in range(taps):
            row = _clamped(y + dy - pad, height)
            for dx in range(taps):
                col = _clamped(x + dx - pad, width)
                red, green, blue = _unit(image[row, col, 0]), _unit(image[row, col, 1]), _unit(image[row, col, 2])
                tap = dy * taps + dx
                first_r += weights[tap] * red
                first_g += weights[taps * taps + tap] * green
                first_b += weights[2 * taps * taps + tap] * blue
                if pair:
                    other_r += weights[second + tap] * red
                    other_g += weights[second + taps * taps + tap] * green
                    other_b += weights[second + 2 * taps * taps + tap] * blue
        if pair:
            first_r += pick * (other_r - first_r)
            first_g += pick * (other_g - first_g)
            first_b += pick * (other_b - first_b)
        out[y, x, 0] = min(max(first_r, low), high)
        out[y, x, 1] = min(max(first_g, low), high)
        out[y, x, 2] = min(max(first_b, low), high)

    return write


def filter_kernel(weights: np.ndarray, bias: np.ndarray):
    """The kernel ``(image, low, high, out)`` that filters ``image`` (H, W, 3) into ``out`` through ``weights``
    (n, 3, k, k) and ``bias`` (n, 3), compiled in as constants (read from global memory, they cost the filter
    0.49 ms against 0.34 at 2048² on the lent H200); launched with blocks of :data:`THREADS`. For a pair the block
    first makes its tiles of luma, gradient product and product smoothed along x in shared memory (named stages,
    each tile with the next one's halo), so the filter is one launch. Kernels are kept per filter."""
    weights = np.ascontiguousarray(weights, dtype=np.float32)
    bias = np.ascontiguousarray(bias, dtype=np.float32).reshape(weights.shape[0], 3)
    return _compiled(weights.shape[2], weights.shape[0] > 1, weights.tobytes(), bias.tobytes())


@functools.lru_cache(maxsize=16)
def _compiled(taps: int, pair: bool, weight_bytes: bytes, bias_bytes: bytes):
    """:func:`filter_kernel` for the flat float32 weights and biases as bytes (the cache's key)."""
    flat_weights = np.frombuffer(weight_bytes, dtype=np.float32).copy()
    flat_bias = np.frombuffer(bias_bytes, dtype=np.float32).copy()
    write = _filter_pixel(taps, pair)
    if not pair:
        @cuda.jit
        def single(image, low, high, out):
            x, y = cuda.grid(2)
            if y < out.shape[0] and x < out.shape[1]:
                write(image, cuda.const.array_like(flat_weights), cuda.const.array_like(flat_bias), float32(0.0),
                      low, high, out, y, x)

        return single

    @cuda.jit
    def paired(image, low, high, out):
        smoothing = cuda.const.array_like(SMOOTHING)
        luma = cuda.shared.array(_LUMA_TILE, float32)
        product = cuda.shared.array(_PRODUCT_TILE, float32)
        across = cuda.shared.array(_ACROSS_TILE, float32)
        y0, x0 = cuda.blockIdx.y * THREADS[1], cuda.blockIdx.x * THREADS[0]
        _luma_stage(image, cuda.const.array_like(LUMA), y0, x0, luma)
        cuda.syncthreads()
        _product_stage(image.shape[0], image.shape[1], y0, x0, luma, product)
        cuda.syncthreads()
        _across_stage(smoothing, product, across)
        cuda.syncthreads()
        x, y = cuda.grid(2)
        if y < out.shape[0] and x < out.shape[1]:
            write(image, cuda.const.array_like(flat_weights), cuda.const.array_like(flat_bias),
                  _second_picked(smoothing, across), low, high, out, y, x)

    return paired


@cuda.jit
def _gather_every_nth(array, step, sample):
    """``sample[j, i, :]`` = ``array[j * step, i * step, :]``."""
    i, j = cuda.grid(2)
    if j < sample.shape[0] and i < sample.shape[1]:
        for c in range(sample.shape[2]):
            sample[j, i, c] = array[j * step, i * step, c]


class DeviceScratch:
    """Device arrays kept between frames by name, made anew only when the shape changes: the device's
    :class:`~volsr_core.runtime.base_filter.Scratch` (an allocation costs about 0.16 ms a 40 MB buffer on the lent
    H200, docs/performance-gpu.md). One per caller."""

    def __init__(self) -> None:
        self._buffers: dict[str, object] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: type = np.float32):
        """The device array ``name`` of ``shape`` (contents undefined)."""
        buffer = self._buffers.get(name)
        if buffer is None or tuple(buffer.shape) != shape or buffer.dtype != dtype:
            buffer = self._buffers[name] = cuda.device_array(shape, dtype=dtype)
        return buffer


def every_nth(array, step: int, scratch: DeviceScratch | None = None):
    """``array[::step, ::step]`` of an (h, w, C) float32 device array (a strided view of a frame's buffer, say),
    gathered on the device into a device array: what a statistic over a sample of the frame needs, its
    ``copy_to_host()`` without the frame's other channels and pixels travelling (a strided view's copy would bring
    its whole span). The gather is queued, not waited for: the copy waits for it (and for what was queued before it).
    ``scratch`` keeps the sample's device buffer between calls."""
    rows, cols = (array.shape[0] + step - 1) // step, (array.shape[1] + step - 1) // step
    shape = (rows, cols, array.shape[2])
    sample = cuda.device_array(shape, dtype=np.float32) if scratch is None else scratch.get("every_nth", shape)
    _gather_every_nth[_blocks(cols, rows), THREADS](array, step, sample)
    return sample


class CudaBaseFilter:
    """One base filter (weights (n, 3, k, k), bias (n, 3), n = 1 or an orientation pair) on the GPU, its weights
    compiled into its kernel (:func:`filter_kernel`). ``filter(image)`` takes a device (or host) (H, W, 3) float32
    image and returns a new device array, what ``filter_image(image, weights, bias, clip_output=...)`` returns, in one
    kernel launch."""

    def __init__(self, weights: np.ndarray, bias: np.ndarray):
        self._kernel = filter_kernel(weights, bias)

    def filter(self, image, clip_output: bool = False):
        """The filtered image (a new (H, W, 3) float32 device array); ``clip_output`` clips it to [0, 1]."""
        if not hasattr(image, "copy_to_host"):  # a host image: copied to the device
            image = cuda.to_device(np.ascontiguousarray(image, dtype=np.float32))
        height, width = image.shape[:2]
        low, high = (0.0, 1.0) if clip_output else (-_FLOAT32_MAX, _FLOAT32_MAX)
        out = cuda.device_array((height, width, 3), dtype=np.float32)
        self._kernel[_blocks(width, height), THREADS](image, np.float32(low), np.float32(high), out)
        return out
