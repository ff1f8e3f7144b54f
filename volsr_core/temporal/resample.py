"""Single-frame resampling: bilinear and bicubic (Keys) upscaling and resizing of images.

Pixel-centre convention (docs/conventions.md): output pixel X samples input continuous coordinate
(X + 0.5) * n_in / n_out, edges repeated. ``upscale_bilinear`` and ``upscale_bicubic`` are the
single-frame baselines (what VTK and 3D Slicer show while interacting at reduced resolution, and
bicubic as in super-resolution papers); ``resize_*`` stretch an image over any output size, as VTK
stretches a reduced-size rendering over the viewport.
"""
from __future__ import annotations

import numba
import numpy as np


def _keys_cubic(d: np.ndarray, a: float) -> np.ndarray:
    """Keys' cubic convolution kernel at distances ``d`` (in pixels, 0 <= d < 2)."""
    near = ((a + 2.0) * d - (a + 3.0)) * d * d + 1.0
    far = ((a * d - 5.0 * a) * d + 8.0 * a) * d - 4.0 * a
    return np.where(d <= 1.0, near, far)


def _axis_taps(n_in: int, n_out: int, cubic: bool, a: float) -> tuple[np.ndarray, np.ndarray]:
    """Input indices and weights, each (n_out, taps), along one axis, edge pixels repeated.

    Output pixel X's centre lies at input index-space position s = (X + 0.5) * n_in / n_out - 0.5
    (input pixel i's centre at i); it takes the 2 linear taps or the 4 Keys-cubic taps around s.
    """
    s = (np.arange(n_out) + 0.5) * n_in / n_out - 0.5
    i0 = np.floor(s).astype(np.int64)
    offsets = np.arange(-1, 3) if cubic else np.arange(0, 2)
    d = np.abs(s[:, None] - (i0[:, None] + offsets))
    weights = _keys_cubic(d, a) if cubic else 1.0 - d
    return np.clip(i0[:, None] + offsets, 0, n_in - 1), weights.astype(np.float32)


@numba.njit(fastmath=True, boundscheck=False, cache=True)
def _resample_row(y, planes, rows, row_w, cols, col_w, out):
    """out[y, X] = sum over taps of row_w[y, i] col_w[X, j] planes[rows[y, i], cols[X, j]]."""
    for x in range(out.shape[1]):
        for c in range(out.shape[2]):
            acc = 0.0
            for i in range(rows.shape[1]):
                r = rows[y, i]
                line = 0.0
                for j in range(cols.shape[1]):
                    line += col_w[x, j] * planes[r, cols[x, j], c]
                acc += row_w[y, i] * line
            out[y, x, c] = acc


@numba.njit(fastmath=True, boundscheck=False, cache=True)
def _linear_row(y, planes, rows, row_w, cols, col_w, out):
    """:func:`_resample_row` for 2 x 2 taps (bilinear), its loops unrolled: 0.33-0.44 of its time
    (``benchmarks/bench_resize.py``)."""
    r0, r1 = rows[y, 0], rows[y, 1]
    a0, a1 = row_w[y, 0], row_w[y, 1]
    for x in range(out.shape[1]):
        c0, c1 = cols[x, 0], cols[x, 1]
        b0, b1 = col_w[x, 0], col_w[x, 1]
        for c in range(out.shape[2]):
            out[y, x, c] = (a0 * (b0 * planes[r0, c0, c] + b1 * planes[r0, c1, c])
                            + a1 * (b0 * planes[r1, c0, c] + b1 * planes[r1, c1, c]))


@numba.njit(parallel=True, cache=True)
def _resample_kernel(planes, rows, row_w, cols, col_w, out):
    if rows.shape[1] == 2 and cols.shape[1] == 2:
        for y in numba.prange(out.shape[0]):
            _linear_row(y, planes, rows, row_w, cols, col_w, out)
    else:
        for y in numba.prange(out.shape[0]):
            _resample_row(y, planes, rows, row_w, cols, col_w, out)


def _resize(image: np.ndarray, height: int, width: int, cubic: bool, a: float = -0.5) -> np.ndarray:
    """Resampling of an (h, w[, C]) image to (height, width[, C]) with separable taps, one numba thread
    team over output rows (no BLAS: numpy's threads would compete with numba's for the cores)."""
    image = np.asarray(image, dtype=np.float32)
    h, w = image.shape[:2]
    planes = np.ascontiguousarray(image.reshape(h, w, -1))
    out = np.empty((height, width, planes.shape[2]), dtype=np.float32)
    _resample_kernel(planes, *_axis_taps(h, height, cubic, a), *_axis_taps(w, width, cubic, a), out)
    return out.reshape((height, width) + image.shape[2:])


def _upscale(lr: np.ndarray, scale: int, cubic: bool, a: float = -0.5) -> np.ndarray:
    """Upscaling of an (h, w[, C]) image by an integer ``scale``."""
    if scale < 1 or int(scale) != scale:
        raise ValueError(f"scale must be a positive integer, got {scale}")
    h, w = np.shape(lr)[:2]
    return _resize(lr, h * int(scale), w * int(scale), cubic, a)


def resize_bilinear(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bilinear resampling of an (h, w[, C]) image to exactly ``width`` x ``height``, float32.

    The image covers the same view at every size (as VTK stretches a reduced-size rendering over
    the viewport); pixel-centre convention, edges repeated. At integer ratios it is
    :func:`upscale_bilinear`.
    """
    return _resize(image, int(height), int(width), cubic=False)


def resize_bicubic(image: np.ndarray, width: int, height: int, a: float = -0.5) -> np.ndarray:
    """Like :func:`resize_bilinear` with Keys' cubic kernel (:func:`upscale_bicubic` at integer ratios);
    not clamped."""
    return _resize(image, int(height), int(width), cubic=True, a=a)


def upscale_bilinear(lr: np.ndarray, scale: int) -> np.ndarray:
    """Bilinear upscaling of an (h, w[, C]) image by an integer ``scale``, float32.

    Pixel-centre convention (docs/conventions.md): HR pixel X samples LR continuous coordinate
    (X + 0.5) / scale, edges repeated; the same as ``torch.nn.functional.interpolate(...,
    mode="bilinear", align_corners=False)``.
    """
    return _upscale(lr, scale, cubic=False)


def upscale_bicubic(lr: np.ndarray, scale: int, a: float = -0.5) -> np.ndarray:
    """Bicubic (Keys cubic convolution, parameter ``a``) upscaling by an integer ``scale``, float32.

    Same convention as :func:`upscale_bilinear`. ``a = -0.5`` is Keys' choice (MATLAB's
    ``imresize``, the usual super-resolution baseline); ``a = -0.75`` matches PyTorch and OpenCV.
    Values can overshoot the input range next to sharp transitions; they are not clamped.
    """
    return _upscale(lr, scale, cubic=True, a=a)
