"""Variant XS's base filter as CUDA kernels (numba-cuda), on device arrays: what :func:`~volsr_core.runtime.
base_filter.filter_image` does on the CPU, one thread per pixel, so a TAAU estimate made on the GPU is filtered
there and only the (H, W, 3) result needs to leave the device.

The same sums in the same order as the CPU kernels (which lay the image out in padded planes first so that their
rows vectorise; here each thread reads its taps with the indices clamped to the image instead): the input clipped
to [0, 1], edge pixels repeated past the border; for a filter pair the orientation test of
:func:`~volsr_core.sr.network.second_orientation` (luma, central differences, their product smoothed along x then
y, negative picks the second filter) in three passes. Tested against the CPU kernels in Numba's CUDA simulator
(``tests/test_temporal_cuda.py``). Importing this module needs ``numba.cuda``.
"""
from __future__ import annotations

import numpy as np

if not hasattr(np, "row_stack"):  # NumPy >= 2.5 removed it; numba-cuda <= 0.30 still overloads it at import
    np.row_stack = np.vstack

from numba import cuda, float32  # noqa: E402

from volsr_core.runtime.base_filter import _FLOAT32_MAX, LUMA, SMOOTHING  # noqa: E402

THREADS = (16, 8)


def _blocks(width: int, height: int) -> tuple[int, int]:
    return (width + THREADS[0] - 1) // THREADS[0], (height + THREADS[1] - 1) // THREADS[1]


@cuda.jit(device=True, inline=True)
def _clipped(image, y, x, c):
    """``image[y, x, c]`` with (y, x) clamped to the image, clipped to [0, 1]."""
    y = min(max(y, 0), image.shape[0] - 1)
    x = min(max(x, 0), image.shape[1] - 1)
    return min(max(image[y, x, c], float32(0.0)), float32(1.0))


@cuda.jit
def _luma(image, weights, luma):
    """``luma`` (H, W): the weighted sum of the clipped channels."""
    x, y = cuda.grid(2)
    if y < luma.shape[0] and x < luma.shape[1]:
        value = weights[0] * _clipped(image, y, x, 0)
        for c in range(1, image.shape[2]):
            value += weights[c] * _clipped(image, y, x, c)
        luma[y, x] = value


@cuda.jit(device=True, inline=True)
def _gradient_product(luma, y, x):
    """The product of the luma's central differences along x and y at (y, x) clamped to the image (edges repeated)."""
    h, w = luma.shape[0], luma.shape[1]
    y = min(max(y, 0), h - 1)
    x = min(max(x, 0), w - 1)
    across = float32(0.5) * (luma[y, min(x + 1, w - 1)] - luma[y, max(x - 1, 0)])
    down = float32(0.5) * (luma[min(y + 1, h - 1), x] - luma[max(y - 1, 0), x])
    return across * down


@cuda.jit
def _smooth_across(luma, taps, across):
    """``across`` (H, W): the gradient product smoothed along x by ``taps`` (the product's edge values repeated)."""
    x, y = cuda.grid(2)
    if y < across.shape[0] and x < across.shape[1]:
        r = taps.shape[0] // 2
        value = float32(0.0)
        for i in range(taps.shape[0]):
            value += taps[i] * _gradient_product(luma, y, x + i - r)
        across[y, x] = value


@cuda.jit
def _pick_second(across, taps, second):
    """``second`` (H, W) uint8: 1 where ``across`` smoothed along y by ``taps`` (edge rows repeated) is negative."""
    x, y = cuda.grid(2)
    h = across.shape[0]
    if y < h and x < across.shape[1]:
        r = taps.shape[0] // 2
        value = float32(0.0)
        for i in range(taps.shape[0]):
            value += taps[i] * across[min(max(y + i - r, 0), h - 1), x]
        second[y, x] = 1 if value < 0 else 0


@cuda.jit
def _filter_pixels(image, weights, bias, second, pair, low, high, out):
    """``out`` (H, W, C): per channel the bias plus the k x k taps of the clipped, edge-repeated image through
    ``weights`` (n, C, k, k): filter 0, or with ``pair`` filter ``second[y, x]`` of the two (both summed, then
    blended by 0 or 1, as the CPU kernel), clamped to [``low``, ``high``]."""
    x, y = cuda.grid(2)
    if y >= out.shape[0] or x >= out.shape[1]:
        return
    taps = weights.shape[2]
    pad = taps // 2
    pick = float32(second[y, x]) if pair else float32(0.0)
    for c in range(out.shape[2]):
        first = bias[0, c]
        other = bias[1, c] if pair else float32(0.0)
        for dy in range(taps):
            for dx in range(taps):
                tap = _clipped(image, y + dy - pad, x + dx - pad, c)
                first += weights[0, c, dy, dx] * tap
                if pair:
                    other += weights[1, c, dy, dx] * tap
        out[y, x, c] = min(max(first + pick * (other - first), low), high)


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
    """One base filter (weights (n, 3, k, k), bias (n, 3), n = 1 or an orientation pair) on the GPU; its weights and
    work buffers stay there between frames. ``filter(image)`` takes a device (or host) (H, W, 3) float32 image and
    returns a new device array, what ``filter_image(image, weights, bias, clip_output=...)`` returns."""

    def __init__(self, weights: np.ndarray, bias: np.ndarray):
        weights = np.ascontiguousarray(weights, dtype=np.float32)
        self.pair = weights.shape[0] > 1
        self.weights = cuda.to_device(weights)
        self.bias = cuda.to_device(np.ascontiguousarray(np.reshape(bias, (weights.shape[0], -1)), dtype=np.float32))
        self._luma_weights, self._smoothing = cuda.to_device(LUMA), cuda.to_device(SMOOTHING)
        self._scratch = DeviceScratch()

    def filter(self, image, clip_output: bool = False):
        """The filtered image (a new (H, W, 3) float32 device array); ``clip_output`` clips it to [0, 1]."""
        if not hasattr(image, "copy_to_host"):  # a host image: copied to the device
            image = cuda.to_device(np.ascontiguousarray(image, dtype=np.float32))
        height, width = image.shape[:2]
        blocks = _blocks(width, height)
        second = self._scratch.get("second", (height, width), np.uint8)
        if self.pair:
            luma, across = self._scratch.get("luma", (height, width)), self._scratch.get("across", (height, width))
            _luma[blocks, THREADS](image, self._luma_weights, luma)
            _smooth_across[blocks, THREADS](luma, self._smoothing, across)
            _pick_second[blocks, THREADS](across, self._smoothing, second)
        low, high = (0.0, 1.0) if clip_output else (-_FLOAT32_MAX, _FLOAT32_MAX)
        out = cuda.device_array((height, width, 3), dtype=np.float32)
        _filter_pixels[blocks, THREADS](image, self.weights, self.bias, second, self.pair, np.float32(low),
                                       np.float32(high), out)
        return out
