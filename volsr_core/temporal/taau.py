"""Temporal upsampling (TAAU): jittered low-resolution frames accumulated into a sharper high-resolution one.

The design holds up under camera motion; it was chosen by measurement (docs/temporal.md, "TAAU under
motion" and "Fine sampling"): against a 16-spp reference at 512² and 1024², it beats the unjittered
reduced-size render + bilinear upscale at 2x and 4x on every benchmark volume at 2 and 5 degrees of
orbit per frame (at 1024² and 5° by 0.00-0.27 dB), and converges on a still camera. Per HR pixel:

1. **Current estimate**: the 2x2 LR samples around the HR pixel centre, weighted by a Gaussian
   of their distance (``sigma`` LR px while the view rotates, ``still_sigma_hr`` HR px without
   rotation, ``static_sigma_hr`` when nothing moves at all), normalised; the sum of
   the weights is the estimate's confidence ``a`` (about 1 where a sample landed on the pixel).
   Where the output samples the volume finely (the LR frame's ``pixels_per_voxel`` times the scale:
   output pixels across the smallest voxel spacing, above ``smooth_between[0]``) and the view
   rotates, the frame is smooth at the pixel scale: the splat's weights are blended with bilinear
   ones, by up to ``smooth_tent`` at ``smooth_between[1]`` and beyond, and the history cap (step 6)
   shrinks by up to the factor ``smooth_count``: bilinear interpolation of such a frame is nearly
   exact, while the history (re-projected under rotation) is not.
2. **Motion**: the nearest LR sample's vector (not interpolated: bilinear motion smears
   foreground and background vectors across silhouettes).
3. **History**: Catmull-Rom fetch of the HR history (RGB), bilinear accumulated weight ``n``.
4. **Disocclusion**: where the 3x3 LR neighbourhood's motion is not uniform (spread above
   ``dis_motion`` HR px, i.e. parallax between surfaces), the history is dropped when the pixel's
   depth lies more than ``disocclusion`` (quasi-depth units) behind the nearest of the 2x2 history
   depths around the reprojected position. The motion gate keeps jittered still frames from
   tripping the test at silhouettes.
5. **Rectification**: per-channel clamp into the YCoCg min/max box of the 3x3 LR neighbourhood of
   the nearest sample. Where that box is one colour (the background around a volume: 65-85% of a bench
   frame's pixels) the clamp gives that colour whatever the history says, and so does step 1's splat, whose
   2x2 samples lie among the nine: the pixel is that colour, without step 3's colour fetch, the splat or
   the blend (the same values; the fetch skipped: 0.78-0.83 of the kernel's time at 512² and 1024²; the
   splat and the blend too: 0.73-0.87 of that; such a run in a loop of its own, without the history rows' Catmull-Rom
   weights: 0.91-0.94 of that, docs/temporal.md, "Speed").
   Where every pixel's splat confidence ``a`` exceeds the history cap of step 6 (a rotating view at 2x, at 4x by 5°
   a frame or sampled finely: :func:`least_weight`) such a pixel's new weight ``min(n + a, cap)`` is the cap
   whatever its history holds, so not even the history's weight is fetched there, nor the motion spread of step 4
   found (without :attr:`~TemporalUpsampler.side_outputs`, which report ``n``): the same values, 0.61-0.85 of the
   time at 2x and at 1024² 4x (``benchmarks/bench_taau.py``, docs/temporal.md, "Speed").
6. **History length**: ``n`` is capped at ``max_count / (1 + rotation / cap_angle)`` with
   ``rotation`` the view's rotation since the last frame (degrees): shading (headlight) and the
   parallax of semi-transparent layers change the image with the view direction, so history ages
   by rotation, not by pixel motion. Without rotation (a still camera, a pan, a zoom) the cap is
   ``still_count`` and the splat narrows (no bilinear blend), so the image converges towards the
   supersampled one; when nothing moves at all the clamp of step 5 is skipped too (it would stop the
   convergence).
7. ``out = (n * history + a * estimate) / (n + a)``; the new history keeps ``min(n + a, cap)``
   and the pixel's depth (nearest sample's ``motion_depth``).

Positions (docs/conventions.md): LR sample i sits at LR index-space position i (continuous
coordinate i + 0.5 + jitter); HR pixel X's centre is at u = (X + 0.5) / scale - 0.5 - jitter there.

Without depth (``depth=None``) the disocclusion test is off. Feed jitter from
``halton_jitter(frame, jitter_phases(scale))``.
"""
from __future__ import annotations

import functools
import math
from typing import Callable

import numba
import numpy as np

from volsr_core.hashing import sources_sha256
from volsr_core.temporal import stages
from volsr_core.temporal.stages import CPU_STAGES

_NB = dict(fastmath=True, boundscheck=False, cache=True)
_INNER = dict(fastmath=True, boundscheck=False)  # helpers of the kernels below: cached as part of them, not apart
_to_ycocg32, _row_window, _splat_weights = CPU_STAGES.to_ycocg32, CPU_STAGES.sample_window, CPU_STAGES.splat_weights
_to_rgb = CPU_STAGES.to_rgb
_catmull_rom_weights, _history_column = CPU_STAGES.catmull_rom_weights, CPU_STAGES.history_column
_mix, _rectify = CPU_STAGES.catmull_rom_mix, CPU_STAGES.clamp_to_ycocg_bounds
_nearest_depth, _history_weight = CPU_STAGES.nearest_depth, CPU_STAGES.history_weight
STILL_BELOW = 1e-6  # degrees: a view rotating less than this between frames is still (a still camera, a pan, a zoom)
SETTLING_MARGIN = 1.0 + 1e-6  # a splat weight settles a pixel where it exceeds the cap by this factor, past rounding


@numba.njit(**_INNER)
def _column_box(lr, rows, i):
    """YCoCg min and max over LR pixels (rows[0..2], i): (lo0, lo1, lo2, hi0, hi1, hi2), converted in float32."""
    lo0 = lo1 = lo2 = np.float32(1e30)
    hi0 = hi1 = hi2 = np.float32(-1e30)
    for yy in rows:
        c0, c1, c2 = _to_ycocg32(lr[yy, i, 0], lr[yy, i, 1], lr[yy, i, 2])
        lo0, lo1, lo2 = min(lo0, c0), min(lo1, c1), min(lo2, c2)
        hi0, hi1, hi2 = max(hi0, c0), max(hi1, c1), max(hi2, c2)
    return lo0, lo1, lo2, hi0, hi1, hi2


@numba.njit(**_INNER)
def _one_colour(box, j, i):
    """Whether the 3x3 neighbourhood of LR pixel (j, i) is one colour: its YCoCg box (:func:`_prepass_row`) is a
    point."""
    return box[j, i, 0] == box[j, i, 3] and box[j, i, 1] == box[j, i, 4] and box[j, i, 2] == box[j, i, 5]


@numba.njit(**_INNER)
def _prepass_row(j, lr, motion, scale, dis_motion, settled, background, box, shown):
    """LR row j: YCoCg min/max of each 3x3 neighbourhood (box[..., 0:6]) and the parallax flag (box[..., 6]); with
    ``settled`` (every pixel of the frame settles: :func:`_row`) the flag only where the box is not one colour, the
    only pixels the kernel then reads it at (0 elsewhere; its nine vectors: half the prepass's time). ``shown[j]``:
    the first and last column whose colour is not ``background`` (RGB), (w, -1) where none is.

    The box of column i is that of the column boxes of i - 1, i and i + 1 (edges repeated), kept as
    the row is walked: each pixel's colour is converted three times, not nine.
    """
    h, w = lr.shape[0], lr.shape[1]
    j = np.int64(j)
    rows = (max(j - 1, 0), j, min(j + 1, h - 1))
    left = _column_box(lr, rows, 0)
    mid = left
    first, last = w, -1
    for i in range(w):
        if lr[j, i, 0] != background[0] or lr[j, i, 1] != background[1] or lr[j, i, 2] != background[2]:
            first, last = min(first, i), i
        right = _column_box(lr, rows, min(i + 1, w - 1))
        box[j, i, 0] = min(min(left[0], mid[0]), right[0])
        box[j, i, 1] = min(min(left[1], mid[1]), right[1])
        box[j, i, 2] = min(min(left[2], mid[2]), right[2])
        box[j, i, 3] = max(max(left[3], mid[3]), right[3])
        box[j, i, 4] = max(max(left[4], mid[4]), right[4])
        box[j, i, 5] = max(max(left[5], mid[5]), right[5])
        left, mid = mid, right
        if settled and _one_colour(box, j, i):
            box[j, i, 6] = 0.0
            continue
        spread = 0.0
        m0, m1 = motion[j, i, 0], motion[j, i, 1]
        for yy in rows:
            for dx in range(-1, 2):
                xx = min(max(i + dx, 0), w - 1)
                spread = max(spread, abs(motion[yy, xx, 0] - m0) + abs(motion[yy, xx, 1] - m1))
        box[j, i, 6] = 1.0 if scale * spread > dis_motion else 0.0
    shown[j, 0], shown[j, 1] = first, last


@numba.njit(**_NB)
def _moves(motion, eps):
    """Whether any vector of ``motion`` (h, w, 2) has a component of at least ``eps``: stops at the first,
    so a moving frame costs next to nothing, and reads a strided view without copying it."""
    for j in range(motion.shape[0]):
        for i in range(motion.shape[1]):
            if abs(motion[j, i, 0]) >= eps or abs(motion[j, i, 1]) >= eps:
                return True
    return False


@numba.njit(**_INNER)
def _fetch_columns(x, shift, run_tx, sx, width):
    """(ix, ix1, tx, in_run): the history columns HR column ``x`` fetches between (its left and right bilinear taps)
    and the fraction past the left one, for a run whose fetches lie at ``run_tx`` past column x + ``shift``; at the
    history's edge (``in_run`` False) from ``sx``, the fetch's position, clamped to [0, ``width`` - 1]."""
    ix = x + shift
    if 0 <= ix < width - 1:
        return ix, ix + 1, run_tx, True
    sx = min(max(sx, 0.0), width - 1.0)
    ix = int(sx)
    return ix, min(ix + 1, width - 1), sx - ix, False


@numba.njit(**_INNER)
def _row(y, history, has_history, lr, motion, depth, box, cols, runs, scale, jy, inv2s2, tent, cap, disocclusion,
         rectify, out, new_history, keep_aux, aux, least_column_weight, settled):
    hr_h, hr_w = out.shape[0], out.shape[1]
    lr_h, lr_w = lr.shape[0], lr.shape[1]
    ly, y0, y1, dy0, wy0, wy1 = _row_window(y, scale, jy, lr_h, inv2s2)
    # the row settles where every pixel's splat weight a = (wy0 + wy1) * (wx0 + wx1) exceeds the cap (see
    # :func:`least_weight`; ``settled``: every row of the frame does): a flat pixel's weight min(n + a, cap) is then the
    # cap whatever the history holds (n >= 0), so its history is not fetched
    settles = settled or (not keep_aux and (wy0 + wy1) * least_column_weight > cap * SETTLING_MARGIN)
    # The HR pixels whose nearest LR sample is lx (a run: columns runs[lx] .. runs[lx + 1] - 1) share its
    # motion, depth and box, so the history's rows, their Catmull-Rom weights and the disocclusion gate are
    # found once per run; along the run the history is fetched at consecutive columns, so the vertical
    # Catmull-Rom pass of each column (k0..k3, columns ix - 1 .. ix + 2) is kept and slides by one column.
    for lx in range(lr_w):
        d = depth[ly, lx]
        # one colour in all nine (the background around a volume, mostly): the clamp gives that colour whatever the
        # history says and the splat (whose 2x2 samples lie among the nine) gives it too, so the run's pixels are that
        # colour: no Catmull-Rom fetch (48 loads a pixel), splat or blend; only the history's weight is still fetched,
        # and not even that where the row settles
        if settles and rectify and _one_colour(box, ly, lx):
            f0, f1, f2 = _to_rgb(box[ly, lx, 0], box[ly, lx, 1], box[ly, lx, 2])
            for x in range(runs[lx], runs[lx + 1]):
                out[y, x, 0], out[y, x, 1], out[y, x, 2] = f0, f1, f2
                new_history[y, x, 0], new_history[y, x, 1], new_history[y, x, 2] = f0, f1, f2
                new_history[y, x, 3] = cap
                new_history[y, x, 4] = d
            continue
        mx = scale * motion[ly, lx, 0]
        sy = y + scale * motion[ly, lx, 1]
        rows_in = has_history and -0.5 < sy < hr_h - 0.5
        sy = min(max(sy, 0.0), hr_h - 1.0)
        iy = int(sy)
        ty = sy - iy
        iy1 = min(iy + 1, hr_h - 1)
        gated = disocclusion > 0.0 and box[ly, lx, 6] > 0.5
        lo0, lo1, lo2, hi0, hi1, hi2 = box[ly, lx, 0], box[ly, lx, 1], box[ly, lx, 2], box[ly, lx, 3], box[ly, lx, 4], \
            box[ly, lx, 5]
        # _one_colour's test on the bounds already loaded (re-reading the box took 1.03-1.10 times as long at 4x)
        flat = rectify and lo0 == hi0 and lo1 == hi1 and lo2 == hi2
        # along the run the history is fetched at one fraction past consecutive columns (x + floor(mx)): its weights
        # are the run's, found per pixel only where a fetch reaches the history's edge
        shift = int(math.floor(mx))
        run_tx = mx - shift
        if flat:  # in a loop of its own, without the rows' Catmull-Rom weights or a test of ``flat`` per pixel
            f0, f1, f2 = _to_rgb(lo0, lo1, lo2)
            for x in range(runs[lx], runs[lx + 1]):
                wx0, wx1 = cols[x, 3], cols[x, 4]
                a = wy0 * wx0 + wy0 * wx1 + wy1 * wx0 + wy1 * wx1
                n = 0.0
                sx = x + mx
                if rows_in and -0.5 < sx < hr_w - 0.5:
                    ix, ix1, tx, _ = _fetch_columns(x, shift, run_tx, sx, hr_w)
                    if not (gated and d - _nearest_depth(history, iy, iy1, ix, ix1) > disocclusion):
                        n = _history_weight(history, iy, iy1, ix, ix1, tx, ty, cap)
                out[y, x, 0], out[y, x, 1], out[y, x, 2] = f0, f1, f2
                new_history[y, x, 0], new_history[y, x, 1], new_history[y, x, 2] = f0, f1, f2
                new_history[y, x, 3] = min(n + a, cap)
                new_history[y, x, 4] = d
                if keep_aux:
                    seen = 1.0 if n > 0.0 else 0.0
                    aux[y, x, 0], aux[y, x, 1], aux[y, x, 2] = seen * f0, seen * f1, seen * f2
                    aux[y, x, 3] = n / (n + a)
            continue
        rows = (max(iy - 1, 0), iy, iy1, min(iy + 2, hr_h - 1))
        ay = _catmull_rom_weights(ty)
        run_ax = _catmull_rom_weights(run_tx)
        # the splat and blend in float32, as the images: float64 weights converted every load (the kernel now takes
        # 0.96-0.98 of the time it took with them)
        zero, one = np.float32(0.0), np.float32(1.0)
        last_ix = -2
        k0 = k1 = k2 = k3 = (np.float32(0.0), np.float32(0.0), np.float32(0.0))  # the four columns' RGB
        for x in range(runs[lx], runs[lx + 1]):
            # 1. the current estimate: 2x2 Gaussian splat, blended with bilinear weights by ``tent``
            x0 = int(cols[x, 1])
            x1 = int(cols[x, 2])
            v00, v01, v10, v11, va, vinv = _splat_weights(wy0, wy1, cols[x, 3], cols[x, 4], dy0, cols[x, 5], tent)
            w00, w01, w10, w11 = np.float32(v00), np.float32(v01), np.float32(v10), np.float32(v11)
            a, inv = np.float32(va), np.float32(vinv)
            e0 = (w00 * lr[y0, x0, 0] + w01 * lr[y0, x1, 0] + w10 * lr[y1, x0, 0] + w11 * lr[y1, x1, 0]) * inv
            e1 = (w00 * lr[y0, x0, 1] + w01 * lr[y0, x1, 1] + w10 * lr[y1, x0, 1] + w11 * lr[y1, x1, 1]) * inv
            e2 = (w00 * lr[y0, x0, 2] + w01 * lr[y0, x1, 2] + w10 * lr[y1, x0, 2] + w11 * lr[y1, x1, 2]) * inv
            n = zero
            h0 = h1 = h2 = zero
            sx = x + mx
            if rows_in and -0.5 < sx < hr_w - 0.5:
                ix, ix1, tx, in_run = _fetch_columns(x, shift, run_tx, sx, hr_w)
                ax = run_ax if in_run else _catmull_rom_weights(tx)
                # 4. disocclusion (depth, where the neighbourhood shows parallax)
                dropped = False
                if gated:
                    dropped = d - _nearest_depth(history, iy, iy1, ix, ix1) > disocclusion
                if not dropped:  # 3. accumulated weight (bilinear) and Catmull-Rom colour
                    n = np.float32(_history_weight(history, iy, iy1, ix, ix1, tx, ty, cap))
                if n > zero:
                    if ix == last_ix + 1:  # the next column of the run: one new vertical pass
                        k0, k1, k2 = k1, k2, k3
                        k3 = _history_column(history, min(ix + 2, hr_w - 1), rows, ay)
                    elif ix != last_ix:  # a new start: all four columns (the same column again: kept)
                        k0 = _history_column(history, max(ix - 1, 0), rows, ay)
                        k1 = _history_column(history, ix, rows, ay)
                        k2 = _history_column(history, ix1, rows, ay)
                        k3 = _history_column(history, min(ix + 2, hr_w - 1), rows, ay)
                    last_ix = ix
                    h0, h1, h2 = _mix(ax, k0, k1, k2, k3)
                    if rectify:  # 5. clamp into the YCoCg box of the 3x3 LR neighbourhood
                        h0, h1, h2 = _rectify(h0, h1, h2, lo0, lo1, lo2, hi0, hi1, hi2)
            # 7. blend
            if n > zero:
                inv = one / (n + a)
                o0 = (n * h0 + a * e0) * inv
                o1 = (n * h1 + a * e1) * inv
                o2 = (n * h2 + a * e2) * inv
            else:
                o0, o1, o2 = e0, e1, e2
            out[y, x, 0] = o0
            out[y, x, 1] = o1
            out[y, x, 2] = o2
            new_history[y, x, 0] = o0
            new_history[y, x, 1] = o1
            new_history[y, x, 2] = o2
            new_history[y, x, 3] = min(n + a, cap)
            new_history[y, x, 4] = d
            if keep_aux:
                aux[y, x, 0] = h0  # what the history said (reprojected, rectified; 0 where there was none) ...
                aux[y, x, 1] = h1
                aux[y, x, 2] = h2
                aux[y, x, 3] = n / (n + a)  # ... and its share of the blend


def _kernels(sources: str):
    """The prepass and the kernel over rows; closures over ``sources``, the digest of the stage module they compile in
    (:func:`~volsr_core.hashing.sources_sha256`), so that numba's disk cache compiles them anew when it changes."""

    @numba.njit(parallel=True, cache=True)
    def prepass(lr, motion, scale, dis_motion, settled, background, box, shown):
        sources  # noqa: B018 - it keys numba's disk cache on the stage module (hashing.sources_sha256)
        for j in numba.prange(lr.shape[0]):
            _prepass_row(j, lr, motion, scale, dis_motion, settled, background, box, shown)

    @numba.njit(parallel=True, cache=True)
    def kernel(history, has_history, lr, motion, depth, box, cols, runs, scale, jy, inv2s2, tent, cap, disocclusion,
               rectify, out, new_history, keep_aux, aux, least_column_weight, settled):
        sources  # noqa: B018 - it keys numba's disk cache on the stage module (hashing.sources_sha256)
        for y in numba.prange(out.shape[0]):
            _row(y, history, has_history, lr, motion, depth, box, cols, runs, scale, jy, inv2s2, tent, cap,
                 disocclusion, rectify, out, new_history, keep_aux, aux, least_column_weight, settled)

    return prepass, kernel


_prepass, _kernel = _kernels(sources_sha256(stages))


@numba.njit(cache=True)
def _columns(hr_w: int, lr_w: int, scale: int, jx: float, inv2s2: float) -> tuple[np.ndarray, np.ndarray]:
    """Per HR column: nearest LR sample, the 2x2 window's two columns, their Gaussian weights and the
    fractional position between them (the bilinear weight of the second); and the runs of HR columns
    whose nearest LR sample is the same: column lx's run is ``runs[lx]`` .. ``runs[lx + 1] - 1``. One numba
    loop, for each frame of new jitter (at 4x a bench frame: 13 µs a call for 1024 columns, 26 in numpy)."""
    cols = np.empty((hr_w, 6), dtype=np.float64)
    runs = np.empty(lr_w + 1, dtype=np.int64)
    last = float(lr_w - 1)
    lx = 0
    for x in range(hr_w):
        u = (x + 0.5) / scale - 0.5 - jx
        f = math.floor(u)
        nearest = min(max(math.floor(u + 0.5), 0.0), last)
        cols[x, 0] = nearest
        cols[x, 1] = min(max(f, 0.0), last)
        cols[x, 2] = min(max(f + 1.0, 0.0), last)
        cols[x, 3] = math.exp(-(u - f) ** 2 * inv2s2)
        cols[x, 4] = math.exp(-(u - f - 1.0) ** 2 * inv2s2)
        cols[x, 5] = u - f
        while lx <= nearest:  # the first column whose nearest sample is lx or more
            runs[lx] = x
            lx += 1
    runs[lx:] = hr_w  # samples no column is nearest to (the last ones), and the end
    return cols, runs


def window_of(shown: np.ndarray, scale: int, lr_w: int, reach: int = 2) -> tuple[int, int, int, int]:
    """The HR window (top, bottom, left, right) of an LR frame ``lr_w`` pixels wide at ``scale`` around the columns its
    rows show (``shown`` (h, 2): per row the first and last, (w, -1) for none), widened by ``reach`` LR pixels each way
    and clipped to the frame; (0, 0, 0, 0) where no row shows any."""
    rows = np.flatnonzero(shown[:, 1] >= shown[:, 0])
    if rows.size == 0:
        return 0, 0, 0, 0
    top, bottom = max(int(rows[0]) - reach, 0), min(int(rows[-1]) + 1 + reach, shown.shape[0])
    left = max(int(shown[rows, 0].min()) - reach, 0)
    right = min(int(shown[rows, 1].max()) + 1 + reach, lr_w)
    return top * scale, bottom * scale, left * scale, right * scale


def least_weight(cols: np.ndarray) -> float:
    """The least sum of an HR column's two Gaussian weights (``cols[:, 3] + cols[:, 4]`` of :func:`_columns`; of a row's
    where the columns are those of the rows, with the vertical jitter). A pixel's splat weight ``a`` is the product of
    its column's sum and its row's, so where the two least sums' product exceeds the history cap (by
    :data:`SETTLING_MARGIN`) every pixel of the frame *settles*: a flat pixel's new weight ``min(n + a, cap)`` is the
    cap whatever its history holds, which then is not fetched (with :attr:`TemporalUpsampler.side_outputs`, which report
    ``n``, it is). A rotating view's cap lies below the least ``a`` at 2x and often at 4x (0.52 at ``sigma`` 0.35,
    halfway between four samples; the cap at 2° a frame: 0.5 at 2x, 1 at 4x, a quarter of that sampled finely)."""
    return float((cols[:, 3] + cols[:, 4]).min())


def output_image(out: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """The (H, W, 3) float32 image an upsampler writes its estimate into: ``out`` when given (a ValueError unless it is
    one of ``shape``, C-contiguous), else a new one."""
    if out is None:
        return np.empty(shape + (3,), dtype=np.float32)
    if out.shape != shape + (3,) or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float32 array of shape {shape + (3,)}, got {out.dtype} "
                         f"{out.shape}")
    return out


def checked_jitter(jitter) -> tuple[float, float]:
    """``jitter`` as (jx, jy) floats; a ValueError unless both lie in [-0.5, 0.5) (LR pixels)."""
    jx, jy = float(jitter[0]), float(jitter[1])
    if not (-0.5 <= jx < 0.5 and -0.5 <= jy < 0.5):
        raise ValueError(f"jitter must lie in [-0.5, 0.5), got {jitter}")
    return jx, jy


def view_rotation(camera, previous) -> float:
    """Degrees between two cameras' directions of projection; 0 when either is None."""
    if camera is None or previous is None:
        return 0.0
    c = min(max(float(camera.direction_of_projection @ previous.direction_of_projection), -1.0), 1.0)
    return math.degrees(math.acos(c))


class TemporalUpsampler:
    """Temporal upsampling of jittered LR frames by an integer ``scale`` (one call per frame).

    Defaults are the measured choice (docs/temporal.md): ``sigma`` 0.35 LR px, history cap
    ``max_count / (1 + rotation / cap_angle)`` = scale / (1 + 1.5 * degrees) (``max_count``
    defaults to the scale: 0.5 at 2x and 1 at 4x for a 2 degree/frame orbit), 16 on a still camera
    with the narrower splats, disocclusion at 0.1 quasi-depth behind where the 3x3 motion spreads
    more than 0.5 HR px; from 1.75 to 2.75 output pixels per voxel the splat turns 0.75 bilinear and
    the cap falls to a quarter (512² of our 256-voxel volumes is 1.4-1.7, 1024² is 2.8-3.4).
    ``side_outputs=False`` skips :attr:`last_aux` for a caller that wants the image alone.
    """

    def __init__(self, scale: int, *, sigma: float = 0.35, still_sigma_hr: float = 0.5, static_sigma_hr: float = 0.3,
                 max_count: float | None = None,
                 cap_angle: float = 2.0 / 3.0, still_count: float = 16.0, disocclusion: float = 0.1,
                 dis_motion: float = 0.5, assumed_rotation: float = 2.0,
                 smooth_between: tuple[float, float] = (1.75, 2.75), smooth_tent: float = 0.75,
                 smooth_count: float = 0.25, side_outputs: bool = True):
        if scale < 1 or int(scale) != scale:
            raise ValueError(f"scale must be a positive integer, got {scale}")
        if sigma <= 0 or still_sigma_hr <= 0 or static_sigma_hr <= 0:
            raise ValueError("sigma, still_sigma_hr and static_sigma_hr must be positive")
        max_count = float(scale) if max_count is None else max_count
        if max_count <= 0 or cap_angle <= 0 or still_count <= 0:
            raise ValueError("max_count, cap_angle and still_count must be positive")
        if not 0 < smooth_between[0] < smooth_between[1] or not 0 <= smooth_tent <= 1 or not 0 < smooth_count <= 1:
            raise ValueError("need 0 < smooth_between[0] < smooth_between[1], smooth_tent in [0, 1] and "
                             "smooth_count in (0, 1]")
        self.scale = int(scale)
        self.sigma = float(sigma)
        self.still_sigma_hr, self.static_sigma_hr = float(still_sigma_hr), float(static_sigma_hr)
        self.max_count, self.cap_angle, self.still_count = float(max_count), float(cap_angle), float(still_count)
        self.disocclusion, self.dis_motion = float(disocclusion), float(dis_motion)
        self.assumed_rotation = float(assumed_rotation)
        self.smooth_between = (float(smooth_between[0]), float(smooth_between[1]))
        self.smooth_tent, self.smooth_count = float(smooth_tent), float(smooth_count)
        self.side_outputs = bool(side_outputs)
        self.history: np.ndarray | None = None  # (H, W, 5): RGB, accumulated weight, depth
        self.last_aux: np.ndarray | None = None  # (H, W, 4) of the last frame with side_outputs: see __call__
        # per LR row of the last frame, the first and last column not of the background colour it was given; None
        # where none was given or the frame was static (see background_window)
        self._shown: np.ndarray | None = None
        self._shown_rows: np.ndarray | None = None  # the prepass's buffer for it
        self._spare: np.ndarray | None = None
        self._box: np.ndarray | None = None
        self._cols: dict = {}

    def reset(self) -> None:
        """Forget the history: the next frame gives its 2x2 splat estimate only."""
        self.history = None

    def background_window(self) -> tuple[int, int, int, int] | None:
        """The HR window (top, bottom, left, right; bottom and right exclusive) outside which the last estimate is one
        colour, the background's as this TAAU writes it (step 5: a one-colour box's colour, through YCoCg and back);
        (0, 0, 0, 0) where all of it is; None where that is not known: no frame yet, no ``background`` given with it,
        or a static frame, whose unclamped blend of that colour with itself leaves float rounding. It is the LR
        pixels not of the background colour, widened by one LR pixel (their 3x3 boxes) and by one more (the HR pixels
        a jittered sample is nearest to reach one LR pixel past its own)."""
        return None if self._shown is None else window_of(self._shown, self.scale, self._box.shape[1])

    def smoothing(self, pixels_per_voxel: float | None) -> float:
        """How far towards the smooth settings a rotating frame goes, in [0, 1], for an LR frame with
        ``pixels_per_voxel`` (None: unknown, 0)."""
        if pixels_per_voxel is None or not math.isfinite(pixels_per_voxel):
            return 0.0
        lo, hi = self.smooth_between
        return min(max((pixels_per_voxel * self.scale - lo) / (hi - lo), 0.0), 1.0)

    def _rotation(self, moves: Callable[[], bool], rotation: float | None) -> float:
        """This frame's view rotation in degrees (>= 0): ``rotation``, or where it is unknown (None) 0 when nothing
        moves (``moves()`` False) and else ``assumed_rotation`` (a brisk one)."""
        if rotation is None:
            return self.assumed_rotation if moves() else 0.0
        return max(float(rotation), 0.0)

    def _frame_settings(self, moves: Callable[[], bool], has_history: bool, rotation: float | None,
                        pixels_per_voxel: float | None) -> tuple[bool, bool, float, float, float]:
        """This frame's (static, still, sigma in LR px, history cap, tent share), from whether any motion vector
        moves (``moves()``, asked only where the answer counts: a view of unknown rotation, or a still one with a
        history; on the GPU the answer waits for the device), whether there is a history, the view's rotation
        (degrees, None: unknown) and the pixels per voxel; still: the view does not rotate (a still camera, a pan,
        a zoom), static: nothing moves at all."""
        moves = functools.cache(moves)  # asked at most once
        rotation = self._rotation(moves, rotation)
        still = rotation < STILL_BELOW  # no view rotation: a still camera, a pan, a zoom
        static = still and has_history and not moves()
        sigma = (self.static_sigma_hr if static else self.still_sigma_hr) / self.scale if still else self.sigma
        cap = self.still_count if still else self.max_count / (1.0 + rotation / self.cap_angle)
        smooth = 0.0 if still else self.smoothing(pixels_per_voxel)
        cap *= 1.0 - (1.0 - self.smooth_count) * smooth
        return static, still, sigma, cap, self.smooth_tent * smooth

    def _columns(self, lr_w: int, jx: float, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """:func:`_columns` of this LR width, horizontal jitter and sigma, kept between frames (the Halton
        jitter repeats)."""
        key = (lr_w, jx, sigma)
        columns = self._cols.get(key)
        if columns is None:
            if len(self._cols) > 512:
                self._cols.clear()
            columns = self._cols[key] = _columns(lr_w * self.scale, lr_w, self.scale, jx,
                                                 1.0 / (2.0 * sigma * sigma))
        return columns

    def __call__(self, lr_color: np.ndarray, lr_motion: np.ndarray, jitter: tuple[float, float],
                 depth: np.ndarray | None = None, rotation: float | None = None,
                 pixels_per_voxel: float | None = None, *, background=None,
                 out: np.ndarray | None = None) -> np.ndarray:
        """Accumulate one LR frame; returns a new (h * scale, w * scale, 3) float32 image, or ``out`` (of that shape,
        C-contiguous) written with it: for a caller done with the last one (a new 1024² image costs about 1 ms of
        page faults a frame). ``background``: the RGB the frame was composited over, for :meth:`background_window`.

        ``lr_color`` (h, w, 3); ``lr_motion`` (h, w, 2) in LR pixels; ``jitter`` (jx, jy) in
        [-0.5, 0.5); ``depth`` (h, w) the renderer's ``motion_depth`` (or ``depth``) buffer, None
        turns the disocclusion test off; ``rotation`` the view's rotation since the previous frame
        in degrees (:func:`view_rotation`): 0 (a still camera, a pan or a zoom) accumulates a long
        history with the narrow kernel; None (unknown) treats the frame as still only where every
        motion vector is zero, else as rotating by ``assumed_rotation`` degrees; ``pixels_per_voxel``
        the LR frame's pixels across the volume's smallest voxel spacing
        (:attr:`~volsr_core.render.features.FeatureFrame.pixels_per_voxel`), None when unknown (then
        no smoothing: the choice for frames that sample the volume coarsely).

        With ``side_outputs`` (the default) :attr:`last_aux` then holds what the blend threw away, (H, W, 4):
        the reprojected, rectified history colour (0 where there was none) and its share of the blend,
        n / (n + a) in [0, 1); without, it is None and the kernel writes none of it (a quarter less to write).
        """
        # read where they lie: the renderer's buffers are channel views of one (h, w, 15) array, and copying
        # them out cost more than the kernels' strided reads (1024² output: about 3 ms a frame)
        lr = np.asarray(lr_color, dtype=np.float32)
        motion = np.asarray(lr_motion, dtype=np.float32)
        if lr.ndim != 3 or lr.shape[2] != 3 or motion.shape != lr.shape[:2] + (2,):
            raise ValueError(f"expected colour (h, w, 3) and motion (h, w, 2), got {lr_color.shape} and "
                             f"{lr_motion.shape}")
        jx, jy = checked_jitter(jitter)
        if depth is None:
            depth_arr, disocclusion = np.ones(lr.shape[:2], dtype=np.float32), 0.0
        else:
            depth_arr, disocclusion = np.asarray(depth, dtype=np.float32), self.disocclusion
            if depth_arr.shape != lr.shape[:2]:
                raise ValueError(f"depth must be (h, w), got {depth_arr.shape}")
        s = self.scale
        h, w = lr.shape[:2]
        shape = (h * s, w * s, 5)
        has = self.history is not None and self.history.shape == shape
        history = self.history if has else np.zeros((1, 1, 5), dtype=np.float32)
        static, _, sigma, cap, tent = self._frame_settings(lambda: _moves(motion, 1e-3), has, rotation,
                                                           pixels_per_voxel)
        inv2s2 = 1.0 / (2.0 * sigma * sigma)
        cols, runs = self._columns(w, jx, sigma)
        if self._box is None or self._box.shape[:2] != (h, w):
            self._box = np.empty((h, w, 8), dtype=np.float32)
            self._shown_rows = np.empty((h, 2), dtype=np.int64)
        least_column = least_weight(cols)
        settled = not static and not self.side_outputs and \
            least_column * least_weight(self._columns(h, jy, sigma)[0]) > cap * SETTLING_MARGIN
        colour = np.full(3, np.nan, np.float32) if background is None else np.asarray(background, np.float32)[:3]
        _prepass(lr, motion, s, self.dis_motion, settled, colour, self._box, self._shown_rows)
        self._shown = None if background is None or static else self._shown_rows
        new_history = self._spare if self._spare is not None and self._spare.shape == shape else \
            np.empty(shape, dtype=np.float32)
        out = output_image(out, shape[:2])
        aux = np.empty(shape[:2] + (4,) if self.side_outputs else (1, 1, 4), dtype=np.float32)
        _kernel(history, has, lr, motion, depth_arr, self._box, cols, runs, s, jy, inv2s2, tent, cap, disocclusion,
                not static, out, new_history, self.side_outputs, aux, least_column, settled)
        self.last_aux = aux if self.side_outputs else None
        self._spare = self.history if has else None
        self.history = new_history
        return out
