"""Single-frame resampling: bilinear and bicubic (Keys) upscaling and resizing of images.

Pixel-centre convention (docs/conventions.md): output pixel X samples input continuous coordinate
(X + 0.5) * n_in / n_out, edges repeated. ``upscale_bilinear`` and ``upscale_bicubic`` are the
single-frame baselines (what VTK and 3D Slicer show while interacting at reduced resolution, and
bicubic as in super-resolution papers); ``resize_*`` stretch an image over any output size, as VTK
stretches a reduced-size rendering over the viewport.
"""
from __future__ import annotations

import functools

import numba
import numpy as np

UNCLAMPED = (-float(np.finfo(np.float32).max), float(np.finfo(np.float32).max))  # finite: the kernels use fastmath


def _keys_cubic(d: np.ndarray, a: float) -> np.ndarray:
    """Keys' cubic convolution kernel at distances ``d`` (in pixels, 0 <= d < 2)."""
    near = ((a + 2.0) * d - (a + 3.0)) * d * d + 1.0
    far = ((a * d - 5.0 * a) * d + 8.0 * a) * d - 4.0 * a
    return np.where(d <= 1.0, near, far)


@functools.lru_cache(maxsize=64)
def _axis_taps(n_in: int, n_out: int, cubic: bool, a: float) -> tuple[np.ndarray, np.ndarray]:
    """Input indices and weights, each (n_out, taps), along one axis, edge pixels repeated; computed once per
    lengths and kernel (a stretch repeats them every frame), read-only.

    Output pixel X's centre lies at input index-space position s = (X + 0.5) * n_in / n_out - 0.5
    (input pixel i's centre at i); it takes the 2 linear taps or the 4 Keys-cubic taps around s.
    """
    s = (np.arange(n_out) + 0.5) * n_in / n_out - 0.5
    i0 = np.floor(s).astype(np.int64)
    offsets = np.arange(-1, 3) if cubic else np.arange(0, 2)
    d = np.abs(s[:, None] - (i0[:, None] + offsets))
    weights = _keys_cubic(d, a) if cubic else 1.0 - d
    taps = np.clip(i0[:, None] + offsets, 0, n_in - 1), weights.astype(np.float32)
    for t in taps:
        t.flags.writeable = False
    return taps


@numba.njit(fastmath=True, boundscheck=False, cache=True)
def _across_row(line, cols, col_w, out):
    """Stage 1, along the row: ``out[x * C + c]`` = sum over taps j of ``col_w[x, j] line[cols[x, j], c]`` (2 or 4
    taps, unrolled; (w, C) in, (width * C) out)."""
    channels = line.shape[1]
    if cols.shape[1] == 2:
        for x in range(cols.shape[0]):
            i0, i1, b0, b1 = cols[x, 0], cols[x, 1], col_w[x, 0], col_w[x, 1]
            for c in range(channels):
                out[x * channels + c] = b0 * line[i0, c] + b1 * line[i1, c]
    else:
        for x in range(cols.shape[0]):
            i0, i1, i2, i3 = cols[x, 0], cols[x, 1], cols[x, 2], cols[x, 3]
            b0, b1, b2, b3 = col_w[x, 0], col_w[x, 1], col_w[x, 2], col_w[x, 3]
            for c in range(channels):
                out[x * channels + c] = (b0 * line[i0, c] + b1 * line[i1, c]) + (b2 * line[i2, c] + b3 * line[i3, c])


@functools.lru_cache(maxsize=64)
def _doubling_weights(n_in: int, n_out: int, cubic: bool, a: float) -> np.ndarray:
    """At n_out = 2 n_in, the weights of the even and the odd outputs, (2, taps) float32: :func:`_axis_taps`' rows
    repeat with period 2 (the same weights, the inputs one further each period); else an empty (0, taps). Read-only
    either way, as :func:`_axis_taps`' are: numba types a read-only array apart from a writable one, and a writable
    empty one compiled the resampling kernel a second time for the sizes that do not double."""
    taps = 4 if cubic else 2
    if n_out != 2 * n_in:
        weights = np.zeros((0, taps), np.float32)
    else:
        weights = _axis_taps(n_in, n_out, cubic, a)[1]
        weights = np.ascontiguousarray(weights[2:4] if n_in > 1 else weights[:2])
    weights.flags.writeable = False
    return weights


@numba.njit(fastmath=True, boundscheck=False, cache=True)
def _across_row_doubled(line, phase_w, out):
    """Stage 1 for an RGB row doubled in width: :func:`_across_row`'s sums, outputs 2k and 2k + 1 from one sliding
    window of inputs k - 2 .. k + 2 (edges repeated) instead of each output's gathered taps and weights: output 2k
    takes inputs k - 2 .. k + 1 (cubic; bilinear k - 1, k), output 2k + 1 inputs k - 1 .. k + 2 (bilinear k, k + 1).
    The same sums in about half the time: VolSR's 2x stretch of a 512² image, the whole resize, 1.1 against 2.2 ms on
    the 2 cores (docs/performance.md)."""
    w = line.shape[0]
    e0, e1, o0, o1 = phase_w[0, 0], phase_w[0, 1], phase_w[1, 0], phase_w[1, 1]
    a0 = a1 = a2 = line[0]
    a3 = line[min(1, w - 1)]
    if phase_w.shape[1] == 4:
        e2, e3, o2, o3 = phase_w[0, 2], phase_w[0, 3], phase_w[1, 2], phase_w[1, 3]
        for k in range(w):
            a4 = line[min(k + 2, w - 1)]
            for c in range(3):
                out[6 * k + c] = (e0 * a0[c] + e1 * a1[c]) + (e2 * a2[c] + e3 * a3[c])
                out[6 * k + 3 + c] = (o0 * a1[c] + o1 * a2[c]) + (o2 * a3[c] + o3 * a4[c])
            a0, a1, a2, a3 = a1, a2, a3, a4
    else:
        for k in range(w):
            for c in range(3):
                out[6 * k + c] = e0 * a1[c] + e1 * a2[c]
                out[6 * k + 3 + c] = o0 * a2[c] + o1 * a3[c]
            a1, a2, a3 = a2, a3, line[min(k + 2, w - 1)]


@numba.njit(fastmath=True, boundscheck=False, cache=True)
def _across_planes_doubled(planes, phase_w, out):
    """:func:`_across_row_doubled` (cubic) for a row given as its channels apart, ``planes`` (C, w): the same sums into
    the same interleaved ``out`` (2w * C), from one channel's plane at a time (XS's filter makes its rows so:
    :func:`~volsr_core.runtime.base_filter.filter_image` with ``stretch=2``)."""
    channels, w = planes.shape[0], planes.shape[1]
    e0, e1, e2, e3 = phase_w[0, 0], phase_w[0, 1], phase_w[0, 2], phase_w[0, 3]
    o0, o1, o2, o3 = phase_w[1, 0], phase_w[1, 1], phase_w[1, 2], phase_w[1, 3]
    for c in range(channels):
        line = planes[c]
        a0 = a1 = a2 = line[0]
        a3 = line[min(1, w - 1)]
        for k in range(w):
            a4 = line[min(k + 2, w - 1)]
            out[2 * channels * k + c] = (e0 * a0 + e1 * a1) + (e2 * a2 + e3 * a3)
            out[2 * channels * k + channels + c] = (o0 * a1 + o1 * a2) + (o2 * a3 + o3 * a4)
            a0, a1, a2, a3 = a1, a2, a3, a4


@numba.njit(fastmath=True, boundscheck=False, cache=True)
def _down_row(across, taps, weights, low, high, out):
    """Stage 2, down the column: ``out[k]`` = sum over taps i of ``weights[i] across[taps[i], k]`` (2 or 4 taps, one
    contiguous pass), clamped to [``low``, ``high``]."""
    if taps.shape[0] == 2:
        a0, a1, w0, w1 = across[taps[0]], across[taps[1]], weights[0], weights[1]
        for k in range(out.shape[0]):
            out[k] = min(max(w0 * a0[k] + w1 * a1[k], low), high)
    else:
        a0, a1, a2, a3 = across[taps[0]], across[taps[1]], across[taps[2]], across[taps[3]]
        w0, w1, w2, w3 = weights[0], weights[1], weights[2], weights[3]
        for k in range(out.shape[0]):
            out[k] = min(max((w0 * a0[k] + w1 * a1[k]) + (w2 * a2[k] + w3 * a3[k]), low), high)


@numba.njit(parallel=True, cache=True)
def _mix_rows(across, rows, row_w, low, high, out, top=0, left=0):
    """Stage 2: output row y (of ``rows``' count) from the rows ``rows[y]`` of ``across`` (h, w * C, the input rows
    resampled along x) weighted by ``row_w[y]`` (:func:`_axis_taps` of the height), clamped to [``low``, ``high``],
    into row ``top`` + y of ``out`` (H, W, C) from column ``left`` on (w columns; 0 and 0: all of ``out``); one
    thread team over the rows. Also the second pass of XS's filter and stretch in one
    (:func:`~volsr_core.runtime.base_filter.filter_image` with ``stretch=2``), whose first writes ``across``."""
    channels = out.shape[2]
    flat = out.reshape(out.shape[0], out.shape[1] * channels)
    start = left * channels
    stop = start + across.shape[1]
    for y in numba.prange(rows.shape[0]):
        _down_row(across, rows[y], row_w[y], low, high, flat[top + y][start:stop])


@numba.njit(parallel=True, cache=True)
def _resample_kernel(planes, rows, row_w, cols, col_w, phase_w, low, high, out):
    """Separable: every input row resampled along x (stage 1; an RGB row doubled in width, ``phase_w`` not empty,
    from a sliding window: :func:`_across_row_doubled`), then every output row mixed from those rows (stage 2,
    :func:`_mix_rows`): 2 x 2 or 4 x 4 taps in 2 + 2 or 4 + 4 multiply-adds a pixel (2.3-5 times faster than mixing
    the 2D taps per pixel for bilinear, 10-20 times for cubic, at 1024² on 2 cores: ``benchmarks/bench_resize.py``)."""
    channels, width = planes.shape[2], out.shape[1]
    across = np.empty((planes.shape[0], width * channels), dtype=np.float32)
    for y in numba.prange(planes.shape[0]):
        if phase_w.shape[0] and channels == 3:
            _across_row_doubled(planes[y], phase_w, across[y])
        else:
            _across_row(planes[y], cols, col_w, across[y])
    _mix_rows(across, rows, row_w, low, high, out)


def _resize(image: np.ndarray, height: int, width: int, cubic: bool, a: float = -0.5,
            clamp: tuple[float, float] = UNCLAMPED) -> np.ndarray:
    """Resampling of an (h, w[, C]) image to (height, width[, C]) with separable taps, values clamped to ``clamp``;
    one numba thread team over rows (no BLAS: numpy's threads would compete with numba's for the cores)."""
    image = np.asarray(image, dtype=np.float32)
    h, w = image.shape[:2]
    planes = np.ascontiguousarray(image.reshape(h, w, -1))
    out = np.empty((height, width, planes.shape[2]), dtype=np.float32)
    _resample_kernel(planes, *_axis_taps(h, height, cubic, float(a)), *_axis_taps(w, width, cubic, float(a)),
                     _doubling_weights(w, width, cubic, float(a)),
                     np.float32(clamp[0]), np.float32(clamp[1]), out)
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


def resize_bicubic(image: np.ndarray, width: int, height: int, a: float = -0.5,
                   clamp: tuple[float, float] | None = None) -> np.ndarray:
    """Like :func:`resize_bilinear` with Keys' cubic kernel (:func:`upscale_bicubic` at integer ratios); values
    clamped to ``clamp`` (low, high) in the same pass, or not at all (None)."""
    return _resize(image, int(height), int(width), cubic=True, a=a, clamp=clamp or UNCLAMPED)


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
