"""Whole-frame steps for frames that stay on the GPU (numba-cuda): the stretches and the average of samples.

What native rendering and the "render smaller + bilinear" baseline do after the ray march, on the device, so that
on a CUDA ray caster every method ends with its full-size image where a viewer shows it (VTK stretches a reduced
rendering on the GPU) and the copy to the host is one step, the same for every method:

- :func:`resize_bilinear_device`: :func:`~volsr_core.temporal.resample.resize_bilinear` (the same taps, mixed in
  the CPU kernel's order), one thread per output pixel; :func:`resize_bicubic_device` the same for
  :func:`~volsr_core.temporal.resample.resize_bicubic` (VolSR's stretch, ``Pipeline(..., stretch=k)``);
- :class:`DeviceAverage`: native N spp's box filter, the samples summed in float64 as the CPU sums them.

Importing this module needs ``numba.cuda`` (``pip install 'volsr[cuda]'``); ``NUMBA_ENABLE_CUDASIM=1`` before numba
is imported runs it in the simulator (tiny images only).
"""
from __future__ import annotations

import numpy as np

if not hasattr(np, "row_stack"):  # NumPy >= 2.5 removed it; numba-cuda <= 0.30 still overloads it at import
    np.row_stack = np.vstack

from numba import cuda  # noqa: E402

from volsr_core.temporal.resample import UNCLAMPED, _axis_taps  # noqa: E402

THREADS = (16, 8)
_taps_kept: dict[tuple, tuple] = {}  # (input, output length, cubic, a) -> the device copies of one axis' taps


def _blocks(width: int, height: int) -> tuple[int, int]:
    return (width + THREADS[0] - 1) // THREADS[0], (height + THREADS[1] - 1) // THREADS[1]


@cuda.jit
def _resample_pixels(image, rows, row_w, cols, col_w, low, high, out):
    """Output pixel (x, y), every channel: the taps of ``rows[y]`` and ``cols[x]`` (2 x 2 or 4 x 4) mixed by their
    weights, columns first and in the CPU kernel's pairs (``resample._across_row``, ``resample._down_row``), clamped
    to [``low``, ``high``]."""
    x, y = cuda.grid(2)
    if y < out.shape[0] and x < out.shape[1]:
        for c in range(out.shape[2]):
            if rows.shape[1] == 2:
                total = (row_w[y, 0] * (col_w[x, 0] * image[rows[y, 0], cols[x, 0], c]
                                        + col_w[x, 1] * image[rows[y, 0], cols[x, 1], c])
                         + row_w[y, 1] * (col_w[x, 0] * image[rows[y, 1], cols[x, 0], c]
                                          + col_w[x, 1] * image[rows[y, 1], cols[x, 1], c]))
            else:
                lines = cuda.local.array(4, np.float32)
                for i in range(4):
                    r = rows[y, i]
                    lines[i] = ((col_w[x, 0] * image[r, cols[x, 0], c] + col_w[x, 1] * image[r, cols[x, 1], c])
                                + (col_w[x, 2] * image[r, cols[x, 2], c] + col_w[x, 3] * image[r, cols[x, 3], c]))
                total = ((row_w[y, 0] * lines[0] + row_w[y, 1] * lines[1])
                         + (row_w[y, 2] * lines[2] + row_w[y, 3] * lines[3]))
            out[y, x, c] = min(max(total, low), high)


def _device_taps(n_in: int, n_out: int, cubic: bool, a: float) -> tuple:
    """One axis' taps (indices, weights) on the device, computed once per pair of lengths and kernel."""
    key = (n_in, n_out, cubic, a)
    kept = _taps_kept.get(key)
    if kept is None:
        kept = _taps_kept[key] = tuple(cuda.to_device(np.ascontiguousarray(t))
                                       for t in _axis_taps(n_in, n_out, cubic=cubic, a=a))
    return kept


def _resize_device(image, width: int, height: int, cubic: bool, a: float, clamp: tuple[float, float]):
    h, w, channels = image.shape
    out = cuda.device_array((int(height), int(width), channels), dtype=np.float32)
    _resample_pixels[_blocks(int(width), int(height)), THREADS](
        image, *_device_taps(h, int(height), cubic, a), *_device_taps(w, int(width), cubic, a),
        np.float32(clamp[0]), np.float32(clamp[1]), out)
    return out


def resize_bilinear_device(image, width: int, height: int):
    """A device (h, w, C) float32 image stretched bilinearly to a new device array (height, width, C): the values of
    :func:`~volsr_core.temporal.resample.resize_bilinear` (pixel-centre convention, edges repeated)."""
    return _resize_device(image, width, height, False, 0.0, UNCLAMPED)


def resize_bicubic_device(image, width: int, height: int, a: float = -0.5, clamp: tuple[float, float] | None = None):
    """:func:`~volsr_core.temporal.resample.resize_bicubic` on the device: Keys' cubic kernel with parameter ``a``,
    values clamped to ``clamp`` (low, high) or not at all (None); a new device array (height, width, C)."""
    return _resize_device(image, width, height, True, float(a), clamp or UNCLAMPED)


@cuda.jit
def _add_sample(total, sample, first):
    """``total`` += ``sample`` per pixel; the ``first`` sample is written instead (no zeroed buffer to upload)."""
    x, y = cuda.grid(2)
    if y < total.shape[0] and x < total.shape[1]:
        for c in range(total.shape[2]):
            total[y, x, c] = sample[y, x, c] if first else total[y, x, c] + sample[y, x, c]


@cuda.jit
def _divide(total, n, out):
    x, y = cuda.grid(2)
    if y < out.shape[0] and x < out.shape[1]:
        for c in range(out.shape[2]):
            out[y, x, c] = total[y, x, c] / n


class DeviceAverage:
    """The mean of device (H, W, C) float32 samples, summed in float64 on the device: ``add`` each, then ``mean``."""

    def __init__(self, shape: tuple[int, int, int]):
        self.total = cuda.device_array(shape, dtype=np.float64)
        self.count = 0

    def add(self, sample) -> None:
        _add_sample[_blocks(sample.shape[1], sample.shape[0]), THREADS](self.total, sample, self.count == 0)
        self.count += 1

    def mean(self):
        """A new device float32 array: the samples added so far, averaged."""
        out = cuda.device_array(self.total.shape, dtype=np.float32)
        _divide[_blocks(out.shape[1], out.shape[0]), THREADS](self.total, float(self.count), out)
        return out
