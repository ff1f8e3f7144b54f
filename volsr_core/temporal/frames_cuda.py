"""Whole-frame steps for frames that stay on the GPU (numba-cuda): the bilinear stretch and the average of samples.

What native rendering and the "render smaller + bilinear" baseline do after the ray march, on the device, so that
on a CUDA ray caster every method ends with its full-size image where a viewer shows it (VTK stretches a reduced
rendering on the GPU) and the copy to the host is one step, the same for every method:

- :func:`resize_bilinear_device`: :func:`~volsr_core.temporal.resample.resize_bilinear` (the same taps, mixed in
  the CPU kernel's order), one thread per output pixel;
- :class:`DeviceAverage`: native N spp's box filter, the samples summed in float64 as the CPU sums them.

Importing this module needs ``numba.cuda`` (``pip install 'volsr[cuda]'``); ``NUMBA_ENABLE_CUDASIM=1`` before numba
is imported runs it in the simulator (tiny images only).
"""
from __future__ import annotations

import numpy as np

if not hasattr(np, "row_stack"):  # NumPy >= 2.5 removed it; numba-cuda <= 0.30 still overloads it at import
    np.row_stack = np.vstack

from numba import cuda  # noqa: E402

from volsr_core.temporal.resample import _axis_taps  # noqa: E402

THREADS = (16, 8)
_taps_kept: dict[tuple[int, int], tuple] = {}  # (input, output) length -> the device copies of one axis' taps


def _blocks(width: int, height: int) -> tuple[int, int]:
    return (width + THREADS[0] - 1) // THREADS[0], (height + THREADS[1] - 1) // THREADS[1]


@cuda.jit
def _bilinear_pixels(image, rows, row_w, cols, col_w, out):
    """Output pixel (x, y), every channel: the 2x2 taps of ``rows[y]`` and ``cols[x]`` mixed by their weights, columns
    first (as ``resample._linear_row``; a stage shared with it made the CPU kernel 2-6% slower at 512²)."""
    x, y = cuda.grid(2)
    if y < out.shape[0] and x < out.shape[1]:
        r0, r1, c0, c1 = rows[y, 0], rows[y, 1], cols[x, 0], cols[x, 1]
        a0, a1, b0, b1 = row_w[y, 0], row_w[y, 1], col_w[x, 0], col_w[x, 1]
        for c in range(out.shape[2]):
            out[y, x, c] = (a0 * (b0 * image[r0, c0, c] + b1 * image[r0, c1, c])
                            + a1 * (b0 * image[r1, c0, c] + b1 * image[r1, c1, c]))


def _device_taps(n_in: int, n_out: int) -> tuple:
    """One axis' bilinear taps (indices, weights) on the device, computed once per pair of lengths."""
    kept = _taps_kept.get((n_in, n_out))
    if kept is None:
        kept = _taps_kept[(n_in, n_out)] = tuple(cuda.to_device(np.ascontiguousarray(a))
                                                 for a in _axis_taps(n_in, n_out, cubic=False, a=0.0))
    return kept


def resize_bilinear_device(image, width: int, height: int):
    """A device (h, w, C) float32 image stretched bilinearly to a new device array (height, width, C): the values of
    :func:`~volsr_core.temporal.resample.resize_bilinear` (pixel-centre convention, edges repeated)."""
    h, w, channels = image.shape
    out = cuda.device_array((int(height), int(width), channels), dtype=np.float32)
    _bilinear_pixels[_blocks(int(width), int(height)), THREADS](image, *_device_taps(h, int(height)),
                                                                *_device_taps(w, int(width)), out)
    return out


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
