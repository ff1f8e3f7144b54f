"""Helpers shared by TAA and temporal upsampling: per-pixel numba functions for their kernels.

The per-pixel functions are inlined into their callers at numba's IR level (no call overhead,
no reference counting of the arrays per pixel, which roughly halves TAA's time). Call them from
a plain ``njit`` row function that a ``prange`` loop calls, not from a ``prange`` body itself:
numba's parfor pass mishandles IR-inlined code there.

- YCoCg: history rectification works there because luma and chroma are decorrelated, so an
  axis-aligned box around a neighbourhood's colours is tighter than in RGB (Karis 2014, "High
  Quality Temporal Supersampling").
- Boxes around a YCoCg image's 3x3 neighbourhoods: min/max, or mean -/+ gamma standard
  deviations (Salvi 2016, "An excursion in temporal supersampling").
- Bringing a history colour into such a box: per-channel clamp, or clipping towards its centre.
- History fetches at a continuous position given in pixel-index units (pixel (x, y)'s centre is
  at (x, y) here, i.e. the docs/conventions.md coordinate minus 0.5), clamped to the image:
  bilinear or 4x4 Catmull-Rom.
"""
from __future__ import annotations

import numba
import numpy as np

from volsr_core.hashing import sources_sha256
from volsr_core.temporal import stages
from volsr_core.temporal.stages import CPU_STAGES

CLAMP_MODES = ("minmax", "variance")
REPROJECTIONS = ("bilinear", "catmull_rom")
RECTIFICATIONS = ("clamp", "clip")

_jit = numba.njit(inline="always", fastmath=True, boundscheck=False, cache=True)


def check_options(clamp: str, rectify: str, reprojection: str, variance_gamma: float) -> None:
    """Raise ValueError for an unknown clamp, rectify or reprojection name or a non-positive gamma."""
    for name, value, allowed in (("clamp", clamp, CLAMP_MODES), ("rectify", rectify, RECTIFICATIONS),
                                 ("reprojection", reprojection, REPROJECTIONS)):
        if value not in allowed:
            raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
    if variance_gamma <= 0:
        raise ValueError(f"variance_gamma must be positive, got {variance_gamma}")


to_ycocg = CPU_STAGES.to_ycocg  # RGB to YCoCg: Y = R/4 + G/2 + B/4, Co = (R - B)/2, Cg = G/2 - (R + B)/4
to_rgb = CPU_STAGES.to_rgb  # YCoCg to RGB: R = Y + Co - Cg, G = Y + Cg, B = Y - Co - Cg


@_jit
def box_minmax(ycocg: np.ndarray, x: int, y: int):
    """((lo_y, lo_co, lo_cg), (hi_y, hi_co, hi_cg)): per-channel min and max of the 3x3 block around (x, y).

    ``ycocg`` is (H, W, 3); neighbours beyond the edge repeat the edge pixel.
    """
    h, w = ycocg.shape[0], ycocg.shape[1]
    lo0 = lo1 = lo2 = np.inf
    hi0 = hi1 = hi2 = -np.inf
    for dy in range(-1, 2):
        yy = min(max(y + dy, 0), h - 1)
        for dx in range(-1, 2):
            xx = min(max(x + dx, 0), w - 1)
            c0, c1, c2 = ycocg[yy, xx, 0], ycocg[yy, xx, 1], ycocg[yy, xx, 2]
            lo0, lo1, lo2 = min(lo0, c0), min(lo1, c1), min(lo2, c2)
            hi0, hi1, hi2 = max(hi0, c0), max(hi1, c1), max(hi2, c2)
    return (lo0, lo1, lo2), (hi0, hi1, hi2)


@_jit
def box_variance(ycocg: np.ndarray, x: int, y: int, gamma: float):
    """Like :func:`box_minmax`: the box mean -/+ ``gamma`` standard deviations of the 3x3 block."""
    h, w = ycocg.shape[0], ycocg.shape[1]
    s0 = s1 = s2 = q0 = q1 = q2 = 0.0
    for dy in range(-1, 2):
        yy = min(max(y + dy, 0), h - 1)
        for dx in range(-1, 2):
            xx = min(max(x + dx, 0), w - 1)
            c0, c1, c2 = ycocg[yy, xx, 0], ycocg[yy, xx, 1], ycocg[yy, xx, 2]
            s0, s1, s2 = s0 + c0, s1 + c1, s2 + c2
            q0, q1, q2 = q0 + c0 * c0, q1 + c1 * c1, q2 + c2 * c2
    m0, m1, m2 = s0 / 9.0, s1 / 9.0, s2 / 9.0
    d0 = gamma * np.sqrt(max(q0 / 9.0 - m0 * m0, 0.0))
    d1 = gamma * np.sqrt(max(q1 / 9.0 - m1 * m1, 0.0))
    d2 = gamma * np.sqrt(max(q2 / 9.0 - m2 * m2, 0.0))
    return (m0 - d0, m1 - d1, m2 - d2), (m0 + d0, m1 + d1, m2 + d2)


@numba.njit(fastmath=True, boundscheck=False)  # cached as part of the kernel below, not apart
def _ycocg_row(y: int, rgb: np.ndarray, ycocg: np.ndarray) -> None:
    for x in range(rgb.shape[1]):
        ycocg[y, x, 0], ycocg[y, x, 1], ycocg[y, x, 2] = to_ycocg(rgb[y, x, 0], rgb[y, x, 1], rgb[y, x, 2])


def _ycocg_rows(sources: str):
    """The conversion over rows; a closure over ``sources``, the digest of the stage module it compiles in
    (:func:`~volsr_core.hashing.sources_sha256`), so that numba's disk cache compiles it anew when that changes."""

    @numba.njit(parallel=True, cache=True)
    def kernel(rgb: np.ndarray, ycocg: np.ndarray) -> None:
        sources  # noqa: B018 - it keys numba's disk cache on the stage module (hashing.sources_sha256)
        for y in numba.prange(rgb.shape[0]):
            _ycocg_row(y, rgb, ycocg)

    return kernel


_ycocg_kernel = _ycocg_rows(sources_sha256(stages))


def image_to_ycocg(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 RGB image to a new (H, W, 3) float32 YCoCg image (:func:`to_ycocg`)."""
    ycocg = np.empty_like(rgb)
    _ycocg_kernel(rgb, ycocg)
    return ycocg


@_jit
def clip_to_box(c: tuple[float, float, float], lo: tuple[float, float, float], hi: tuple[float, float, float],
                towards_centre: bool) -> tuple[float, float, float]:
    """Bring colour ``c`` into the box [lo, hi] (unchanged if inside).

    Per-channel clamp, or with ``towards_centre`` a move along the line to the box centre onto its
    surface (Karis 2014, Salvi 2016). Clipping keeps hue but, where one channel's extent is tiny
    (a flat-coloured neighbourhood), the smallest tint mismatch pulls all channels, luma
    included, to the centre: on thin vessels it converges worse (CT_AVM, 160², still camera, 32
    frames against 16 spp: 34.6 dB clipped, 38.4 dB clamped).
    """
    if not towards_centre:
        return min(max(c[0], lo[0]), hi[0]), min(max(c[1], lo[1]), hi[1]), min(max(c[2], lo[2]), hi[2])
    ratio = 1.0
    for i in range(3):
        centre = 0.5 * (hi[i] + lo[i])
        extent = max(0.5 * (hi[i] - lo[i]), 1e-6)
        ratio = max(ratio, abs(c[i] - centre) / extent)
    m0, m1, m2 = 0.5 * (hi[0] + lo[0]), 0.5 * (hi[1] + lo[1]), 0.5 * (hi[2] + lo[2])
    return m0 + (c[0] - m0) / ratio, m1 + (c[1] - m1) / ratio, m2 + (c[2] - m2) / ratio


@_jit
def _catmull_rom_taps(s: float, n: int):
    """Indices (4, clamped to [0, n)) and weights of the Catmull-Rom taps around position ``s``."""
    i0 = int(np.floor(s))
    t = s - i0
    t2, t3 = t * t, t * t * t
    weights = (0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2) + 1.0,
               0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2))
    indices = (max(i0 - 1, 0), i0, min(i0 + 1, n - 1), min(i0 + 2, n - 1))
    return indices, weights


@_jit
def fetch_bilinear(image: np.ndarray, sx: float, sy: float, dst: np.ndarray) -> None:
    """Write ``image`` (H, W, C) bilinearly sampled at index-space (sx, sy), clamped to the image, into ``dst[:C]``."""
    h, w, nc = image.shape
    sx, sy = min(max(sx, 0.0), w - 1.0), min(max(sy, 0.0), h - 1.0)
    x0, y0 = min(int(sx), w - 1), min(int(sy), h - 1)
    x1, y1 = min(x0 + 1, w - 1), min(y0 + 1, h - 1)
    fx, fy = sx - x0, sy - y0
    for c in range(nc):
        top = image[y0, x0, c] + fx * (image[y0, x1, c] - image[y0, x0, c])
        bottom = image[y1, x0, c] + fx * (image[y1, x1, c] - image[y1, x0, c])
        dst[c] = top + fy * (bottom - top)


@_jit
def fetch_catmull_rom(image: np.ndarray, sx: float, sy: float, dst: np.ndarray) -> None:
    """Like :func:`fetch_bilinear` with a 4x4 Catmull-Rom filter (edge pixels repeated; may overshoot)."""
    h, w, nc = image.shape
    sx, sy = min(max(sx, 0.0), w - 1.0), min(max(sy, 0.0), h - 1.0)
    xi, xw = _catmull_rom_taps(sx, w)
    yi, yw = _catmull_rom_taps(sy, h)
    for c in range(nc):
        acc = 0.0
        for j in range(4):
            row = 0.0
            for i in range(4):
                row += xw[i] * image[yi[j], xi[i], c]
            acc += yw[j] * row
        dst[c] = acc


@_jit
def on_screen(sx: float, sy: float, w: int, h: int) -> bool:
    """Whether index-space position (sx, sy) lies on a (w, h) image (within half a pixel of a centre)."""
    return -0.5 < sx < w - 0.5 and -0.5 < sy < h - 0.5


@_jit
def clip_history(colour: np.ndarray, ycocg: np.ndarray, bx: int, by: int, variance: bool, gamma: float,
                 towards_centre: bool) -> None:
    """Bring the RGB colour ``colour[:3]`` in place into the YCoCg box of ``ycocg``'s 3x3 block around (bx, by).

    The box is :func:`box_variance` (with ``gamma``) or :func:`box_minmax`; see :func:`clip_to_box`.
    """
    if variance:
        lo, hi = box_variance(ycocg, bx, by, gamma)
    else:
        lo, hi = box_minmax(ycocg, bx, by)
    c = clip_to_box(to_ycocg(colour[0], colour[1], colour[2]), lo, hi, towards_centre)
    colour[0], colour[1], colour[2] = to_rgb(c[0], c[1], c[2])
