"""The per-pixel stages of temporal upsampling, written once for the CPU and CUDA kernels (as the ray program's).

:func:`build_temporal_stages` takes a decorator (``numba.njit(inline="always")`` for the CPU,
``numba.cuda.jit(device=True, inline=True)`` for CUDA) and returns the stages compiled with it; only scalar
maths, ``math`` functions and array reads appear here, so the same source compiles for both targets.
:data:`CPU_STAGES` is the CPU build the numba kernels of :mod:`~volsr_core.temporal.taau`,
:mod:`~volsr_core.temporal.layered` and :mod:`~volsr_core.temporal.color` call; :mod:`~volsr_core.temporal.cuda`
builds its own.

- ``to_ycocg`` / ``to_rgb``: RGB <-> YCoCg (Y = R/4 + G/2 + B/4, Co = (R - B)/2, Cg = G/2 - (R + B)/4), the
  space whose axis-aligned boxes rectify a history (Karis 2014); ``to_ycocg32`` the same in float32;
- ``sample_window``: along one axis, the LR samples around an HR pixel centre: the nearest, the two of the 2x2
  window, the fraction past the first and the two Gaussian weights (TAAU's step 1);
- ``splat_weights``: the 2x2 splat's weights, its confidence and the factor that normalises it, Gaussian,
  blended with the bilinear weights by ``tent``; the nearest sample alone where the Gaussian has vanished;
- ``catmull_rom_weights``: the four Catmull-Rom weights at a fraction past the second tap (float32, as the
  history is); ``history_column`` and ``catmull_rom_mix``: a history column's vertical Catmull-Rom pass (RGB),
  and the horizontal pass over four of them;
- ``nearest_depth`` and ``history_weight``: a TAAU history's least depth and bilinear accumulated weight at its
  2x2 taps (TAAU's depth test, step 4, and step 3's weight);
- ``bilinear_taps``: four taps of one channel of a layered (K, H, W, C) array, weighted and summed (the layered
  TAAU's splat and its bilinear history fetch);
- ``clamp_to_ycocg_bounds``: an RGB colour clamped per channel into a YCoCg min/max box, in float32 as the
  boxes are (the box's six bounds passed in: the CPU kernel reads them once per run of HR pixels).

Positions (docs/conventions.md): LR sample i sits at LR index-space position i; HR pixel X's centre lies at
u = (X + 0.5) / scale - 0.5 - jitter there.
"""
from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numba
import numpy as np

SPLAT_FLOOR = 1e-30
"""The least confidence a splat keeps (``splat_weights``): its inverse and a quarter of it are ordinary float32 numbers,
where the Gaussian weights of a still view's narrow splat (``still_sigma_hr`` / scale LR px) fall to 1e-98 at 16x and
those of a static view's to 1e-60 at 8x, and the float32 sums made NaN of them."""


class TemporalStages(NamedTuple):
    """The stages of one build (see the module docstring)."""

    to_ycocg: Callable
    to_rgb: Callable
    to_ycocg32: Callable
    sample_window: Callable
    splat_weights: Callable
    catmull_rom_weights: Callable
    nearest_depth: Callable
    history_weight: Callable
    history_column: Callable
    catmull_rom_mix: Callable
    bilinear_taps: Callable
    clamp_to_ycocg_bounds: Callable


def build_temporal_stages(jit: Callable) -> TemporalStages:
    """Compile the stages with ``jit``."""

    @jit
    def to_ycocg(r, g, b):
        """RGB to YCoCg."""
        return 0.25 * r + 0.5 * g + 0.25 * b, 0.5 * (r - b), 0.5 * g - 0.25 * (r + b)

    @jit
    def to_rgb(y, co, cg):
        """YCoCg to RGB: R = Y + Co - Cg, G = Y + Cg, B = Y - Co - Cg."""
        return y + co - cg, y + cg, y - co - cg

    @jit
    def to_ycocg32(r, g, b):
        """:func:`to_ycocg` in float32 (for the boxes of float32 images; float64 there made TAAU 2-4% slower)."""
        return (np.float32(0.25) * r + np.float32(0.5) * g + np.float32(0.25) * b, np.float32(0.5) * (r - b),
                np.float32(0.5) * g - np.float32(0.25) * (r + b))

    @jit
    def sample_window(x, scale, jitter, lr_n, inv2s2):
        """HR index ``x`` along an axis of ``lr_n`` LR samples: (nearest, first, second, fraction past the first,
        weight of the first, weight of the second), indices clamped to [0, lr_n), weights Gaussian
        (exp(-d² * inv2s2), d in LR px)."""
        u = (x + 0.5) / scale - 0.5 - jitter
        nearest = min(max(int(math.floor(u + 0.5)), 0), lr_n - 1)
        f = math.floor(u)
        first = min(max(int(f), 0), lr_n - 1)
        second = min(max(int(f) + 1, 0), lr_n - 1)
        d0 = u - f
        d1 = d0 - 1.0
        return nearest, first, second, d0, math.exp(-d0 * d0 * inv2s2), math.exp(-d1 * d1 * inv2s2)

    @jit
    def splat_weights(wy0, wy1, wx0, wx1, dy0, fx, tent):
        """The 2x2 splat's weights (w00, w01, w10, w11), its confidence ``a`` (the Gaussian weights' sum) and the
        factor ``inv`` that normalises the weighted sum: Gaussian, blended with the bilinear weights at (fx, dy0)
        by ``tent``. Where the Gaussian has all but vanished (``a`` below :data:`SPLAT_FLOOR`: the narrow splat of
        a still view, far from the samples at 8x and more) the nearest sample takes the whole weight at that
        least confidence, so the float32 sums neither overflow nor divide zero by zero."""
        w00, w01, w10, w11 = wy0 * wx0, wy0 * wx1, wy1 * wx0, wy1 * wx1
        a = w00 + w01 + w10 + w11
        if a < SPLAT_FLOOR:
            below, right = dy0 >= 0.5, fx >= 0.5
            w00 = 1.0 if not below and not right else 0.0
            w01 = 1.0 if not below and right else 0.0
            w10 = 1.0 if below and not right else 0.0
            w11 = 1.0 if below and right else 0.0
            a, inv = SPLAT_FLOOR, 1.0
        else:
            inv = 1.0 / a
        if tent > 0.0:
            keep = (1.0 - tent) * inv
            w00 = keep * w00 + tent * (1.0 - dy0) * (1.0 - fx)
            w01 = keep * w01 + tent * (1.0 - dy0) * fx
            w10 = keep * w10 + tent * dy0 * (1.0 - fx)
            w11 = keep * w11 + tent * dy0 * fx
            inv = 1.0
        return w00, w01, w10, w11, a, inv

    @jit
    def catmull_rom_weights(t):
        """The four Catmull-Rom weights at fraction ``t`` in [0, 1) past the second tap, in float32."""
        t = np.float32(t)
        t2 = t * t
        t3 = t2 * t
        h = np.float32(0.5)
        return (h * (-t3 + np.float32(2.0) * t2 - t),
                h * (np.float32(3.0) * t3 - np.float32(5.0) * t2) + np.float32(1.0),
                h * (np.float32(-3.0) * t3 + np.float32(4.0) * t2 + t), h * (t3 - t2))

    @jit
    def nearest_depth(history, iy, iy1, ix, ix1):
        """The least depth (channel 4) of an (H, W, 5) history at its taps (iy, ix), (iy, ix1), (iy1, ix), (iy1, ix1):
        TAAU's disocclusion test compares the pixel's depth with it."""
        return min(min(history[iy, ix, 4], history[iy, ix1, 4]), min(history[iy1, ix, 4], history[iy1, ix1, 4]))

    @jit
    def history_weight(history, iy, iy1, ix, ix1, tx, ty, cap):
        """The accumulated weight (channel 3) of an (H, W, 5) history, bilinear at fractions (tx, ty) past (ix, iy),
        clamped to [0, ``cap``]."""
        top = history[iy, ix, 3] + tx * (history[iy, ix1, 3] - history[iy, ix, 3])
        bottom = history[iy1, ix, 3] + tx * (history[iy1, ix1, 3] - history[iy1, ix, 3])
        return min(max(top + ty * (bottom - top), 0.0), cap)

    @jit
    def history_column(history, c, rows, weights):
        """The vertical Catmull-Rom pass of column ``c`` of an (H, W, >= 3) history over ``rows`` (four indices,
        clamped) with ``weights`` (:func:`catmull_rom_weights`): RGB."""
        r0, r1, r2, r3 = rows
        a0, a1, a2, a3 = weights
        return (a0 * history[r0, c, 0] + a1 * history[r1, c, 0] + a2 * history[r2, c, 0] + a3 * history[r3, c, 0],
                a0 * history[r0, c, 1] + a1 * history[r1, c, 1] + a2 * history[r2, c, 1] + a3 * history[r3, c, 1],
                a0 * history[r0, c, 2] + a1 * history[r1, c, 2] + a2 * history[r2, c, 2] + a3 * history[r3, c, 2])

    @jit
    def catmull_rom_mix(weights, k0, k1, k2, k3):
        """The horizontal Catmull-Rom pass: four columns' RGB (:func:`history_column`) weighted by ``weights``."""
        a0, a1, a2, a3 = weights
        return (a0 * k0[0] + a1 * k1[0] + a2 * k2[0] + a3 * k3[0], a0 * k0[1] + a1 * k1[1] + a2 * k2[1] + a3 * k3[1],
                a0 * k0[2] + a1 * k1[2] + a2 * k2[2] + a3 * k3[2])

    @jit
    def bilinear_taps(layers, k, y0, y1, x0, x1, c, w00, w01, w10, w11):
        """Channel ``c`` of layer ``k`` of a (K, H, W, C) array at the four taps (y0, x0), (y0, x1), (y1, x0),
        (y1, x1), weighted by w00, w01, w10, w11 and summed."""
        return (w00 * layers[k, y0, x0, c] + w01 * layers[k, y0, x1, c]
                + w10 * layers[k, y1, x0, c] + w11 * layers[k, y1, x1, c])

    @jit
    def clamp_to_ycocg_bounds(r, g, b, lo0, lo1, lo2, hi0, hi1, hi2):
        """RGB (r, g, b) clamped per channel into the YCoCg box (lo0, lo1, lo2) .. (hi0, hi1, hi2), back in RGB; the
        conversion in float32, as the boxes are (float64 made the CPU TAAU 4-7% slower, outputs within 2e-7)."""
        y, co, cg = to_ycocg32(np.float32(r), np.float32(g), np.float32(b))
        return to_rgb(min(max(y, lo0), hi0), min(max(co, lo1), hi1), min(max(cg, lo2), hi2))

    return TemporalStages(to_ycocg, to_rgb, to_ycocg32, sample_window, splat_weights, catmull_rom_weights,
                          nearest_depth, history_weight, history_column, catmull_rom_mix, bilinear_taps,
                          clamp_to_ycocg_bounds)


CPU_STAGES = build_temporal_stages(numba.njit(inline="always", fastmath=True, boundscheck=False, cache=True))
