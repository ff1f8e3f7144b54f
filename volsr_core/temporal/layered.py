"""Layered temporal upsampling: TAAU with one history per depth slab, each reprojected by its own vectors.

A ray of a volume rendering shows structures at several depths, which move apart as the view rotates
(vessels in front of vessels, bone behind soft tissue: up to 7 px of parallax per 2° at 512²), while
one motion vector per pixel moves them together; so TAAU's one-layer history goes stale under rotation
(docs/performance.md, "What the 4x points lack"). Here the ray caster cuts each ray into K depth slabs
in its one pass (``RayCaster.render(..., slabs=K)``: per slab its samples' premultiplied RGBA and the
motion vector of their opacity-weighted mean point) and each slab keeps its own HR history. Per HR
pixel and slab, the steps of :class:`~volsr_core.temporal.taau.TemporalUpsampler` on premultiplied RGBA:

1. **Current estimate**: the slab's 2x2 LR samples around the pixel, Gaussian-weighted (``sigma``), blended
   with bilinear weights where the frame samples the volume finely (TAAU's smoothing);
2. **Motion**: the slab's vector at the nearest LR sample, or where that sample's slab is empty, at the
   most opaque sample of the slab in its 3x3 neighbourhood; a slab empty in all nine is empty here
   (its history is cleared and the pixel costs next to nothing);
3. **History**: bilinear fetch of the slab's premultiplied RGBA and accumulated weight;
4. **Rectification**: per-channel clamp into the slab's RGBA min/max box of the 3x3 LR neighbourhood, while
   the view does not rotate (a pan, a zoom: the history is long there, up to ``still_count``) and, by default
   (``clamp_rotating="fine"``), while it rotates where the frame samples the volume finely (TAAU's
   fine-sampling settings apply: above ``smooth_between[0]`` output pixels per voxel); skipped when nothing
   moves at all, as TAAU does. Under rotation the cap keeps the history short and the slabs already keep
   apart what moves apart: at about one output pixel a voxel (most training videos) the clamp threw away more
   good history than stale (docs/temporal.md, "A shorter history"), while sampled finely a shiny look's
   unclamped history keeps the highlights of earlier views (docs/performance.md, "Off the bench");
5. blend as TAAU (``out = (n * history + a * estimate) / (n + a)``, ``n`` capped by the view's rotation,
   ``max_count / (1 + rotation / cap_angle)`` with ``cap_angle`` 0.3 here against TAAU's 2/3: the bilinear
   fetch blurs what it resamples, so a shorter history pays);

then the slabs are composited front to back over the background. No depth test: a structure that
moves in front of another lies in another slab. Settings, caps and the still-camera behaviour are
TAAU's (the same constructor, ``sigma``, ``cap_angle`` and ``smooth_count`` defaulting to this TAAU's own);
the depth test's ``disocclusion`` and ``dis_motion`` are not used.
Measured in docs/temporal.md ("Layered history"); feed it ``halton_jitter(frame, jitter_phases(scale))``.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from volsr_core.hashing import sources_sha256
from volsr_core.render import layout
from volsr_core.render.layout import SLAB_CHANNELS, SLAB_MOTION, SLAB_RGBA
from volsr_core.temporal import stages
from volsr_core.temporal.stages import CPU_STAGES, SPLAT_FLOOR
from volsr_core.temporal.taau import TemporalUpsampler, _moves, checked_jitter, output_image, window_of

_NB = dict(fastmath=True, boundscheck=False, cache=True)
_INNER = dict(fastmath=True, boundscheck=False)  # helpers of the kernels below: cached as part of them, not apart
_row_window, _splat_weights, _taps = CPU_STAGES.sample_window, CPU_STAGES.splat_weights, CPU_STAGES.bilinear_taps
_EMPTY = 1e-4  # a slab with at most this alpha at an LR sample shows nothing there
CLAMP_ROTATING = ("never", "fine", "always")  # where the history is clamped while the view rotates
_INFO = 11  # per slab and LR pixel: RGBA box low (4) and high (4), motion (2), whether the 3x3 shows anything


@numba.njit(**_INNER)
def _reach(shows, k, j, rows, w):
    """The columns (first, last) of LR row ``j`` of slab ``k`` that lie within one column and ``rows`` rows of a sample
    that shows something (``shows`` (K, h, 2): per slab and row, the first and last column that does, or (w, -1));
    (w, -1) where none does."""
    lo, hi = w, -1
    for y in range(max(j - rows, 0), min(j + rows + 1, shows.shape[1])):
        if shows[k, y, 1] >= shows[k, y, 0]:
            lo, hi = min(lo, shows[k, y, 0]), max(hi, shows[k, y, 1])
    return (max(lo - 1, 0), min(hi + 1, w - 1)) if hi >= lo else (w, -1)


@numba.njit(parallel=True, **_NB)
def _widen(src, lo_at, hi_at, alpha_at, motion_at, vertical, box, shows, rows, dst):
    """Per slab and LR pixel of ``src`` (K, h, w, C): over it and its two neighbours in its row (``vertical``: its
    column), the minimum of the four channels from ``lo_at``, the maximum of the four from ``hi_at`` and, of the
    most opaque of the three (alpha at ``alpha_at``; the first among equals, from the left or the top), the alpha
    and the motion at ``motion_at``, into ``dst`` (K, h, w, _INFO): low 0-3, high 4-7, motion 8-9, alpha 10; only at
    the pixels within ``rows`` rows (:func:`_reach`) of a sample that shows something (``shows``), the rest left as it
    was. Without ``box`` the minima and maxima are skipped (low and high left at +1e30 and -1e30)."""
    n_slabs, h, w = src.shape[0], src.shape[1], src.shape[2]
    dy, dx = (1, 0) if vertical else (0, 1)
    for j in numba.prange(h):
        for k in range(n_slabs):
            first, last = _reach(shows, k, j, rows, w)
            for i in range(first, last + 1):
                lo0 = lo1 = lo2 = lo3 = np.float32(1e30)
                hi0 = hi1 = hi2 = hi3 = np.float32(-1e30)
                best = np.float32(_EMPTY)
                mx = my = np.float32(0.0)
                for n in range(-1, 2):
                    y, x = j + n * dy, i + n * dx
                    if y < 0 or y >= h or x < 0 or x >= w:
                        continue
                    if box:
                        lo0, lo1 = min(lo0, src[k, y, x, lo_at]), min(lo1, src[k, y, x, lo_at + 1])
                        lo2, lo3 = min(lo2, src[k, y, x, lo_at + 2]), min(lo3, src[k, y, x, lo_at + 3])
                        hi0, hi1 = max(hi0, src[k, y, x, hi_at]), max(hi1, src[k, y, x, hi_at + 1])
                        hi2, hi3 = max(hi2, src[k, y, x, hi_at + 2]), max(hi3, src[k, y, x, hi_at + 3])
                    if src[k, y, x, alpha_at] > best:
                        best, mx, my = src[k, y, x, alpha_at], src[k, y, x, motion_at], src[k, y, x, motion_at + 1]
                dst[k, j, i, 0], dst[k, j, i, 1], dst[k, j, i, 2], dst[k, j, i, 3] = lo0, lo1, lo2, lo3
                dst[k, j, i, 4], dst[k, j, i, 5], dst[k, j, i, 6], dst[k, j, i, 7] = hi0, hi1, hi2, hi3
                dst[k, j, i, 8], dst[k, j, i, 9], dst[k, j, i, 10] = mx, my, best


@numba.njit(**_INNER)
def _history_column(history, k, iy, iy1, x, uy, ty):
    """Column ``x`` of slab ``k``'s (K, H, W, 5) history blended between rows ``iy`` and ``iy1`` by (``uy``, ``ty``):
    the vertical half of a bilinear fetch, all five channels."""
    return (uy * history[k, iy, x, 0] + ty * history[k, iy1, x, 0],
            uy * history[k, iy, x, 1] + ty * history[k, iy1, x, 1],
            uy * history[k, iy, x, 2] + ty * history[k, iy1, x, 2],
            uy * history[k, iy, x, 3] + ty * history[k, iy1, x, 3],
            uy * history[k, iy, x, 4] + ty * history[k, iy1, x, 4])


@numba.njit(**_INNER)
def _row(y, history, has_history, slabs, info, content, cols, runs, scale, jy, inv2s2, tent, cap, rectify, background,
         out, new_history, shown, spans, acc, splat_rows):
    n_slabs, hr_h, hr_w = new_history.shape[0], new_history.shape[1], new_history.shape[2]
    lr_h, lr_w = slabs.shape[1], slabs.shape[2]
    ly, y0, y1, dy0, wy0, wy1 = _row_window(y, scale, jy, lr_h, inv2s2)
    # the per-pixel sums in float32, as the buffers are: float64 weights converted every load (the kernel now takes
    # 0.84-0.88 of the time it took with them; benchmarks/bench_taau.py --slabs 2, 512² and 1024²)
    zero, one, cap32 = np.float32(0.0), np.float32(1.0), np.float32(cap)
    gy0, gy1, by0, by1 = np.float32(wy0), np.float32(wy1), np.float32(1.0 - dy0), np.float32(dy0)
    row_weight = wy0 + wy1
    # the HR columns where some slab shows something (``content``: per slab and LR row, the first and last LR
    # column that does); the rest of the row is the background
    drawn_lo, drawn_hi = hr_w, 0
    for k in range(n_slabs):
        if content[k, ly, 1] >= content[k, ly, 0]:
            drawn_lo = min(drawn_lo, runs[content[k, ly, 0]])
            drawn_hi = max(drawn_hi, runs[content[k, ly, 1] + 1])
    for x in range(drawn_lo, drawn_hi):
        for c in range(4):
            acc[x, c] = 0.0  # the composite so far: premultiplied RGB and alpha
    for k in range(n_slabs):
        # the splat's vertical half, once per LR column for the HR row (``splat_rows``: the two LR rows' RGBA weighted
        # by the Gaussian, 0-3, and by the bilinear weights, 4-7, where ``tent`` blends them in): each HR pixel then
        # weighs its window's two columns, half the reads of the whole 2x2 window
        if content[k, ly, 1] >= content[k, ly, 0]:
            for lx in range(max(content[k, ly, 0] - 1, 0), min(content[k, ly, 1] + 2, lr_w)):
                for c in range(4):
                    top, bottom = slabs[k, y0, lx, c], slabs[k, y1, lx, c]
                    splat_rows[lx, c] = gy0 * top + gy1 * bottom
                    if tent > 0.0:
                        splat_rows[lx, 4 + c] = by0 * top + by1 * bottom
        # the LR columns to visit: those where the slab shows something and those whose HR pixels the buffer may
        # still hold something other than zeros in (``spans``: per slab and HR row, as the buffer was last written)
        first, last = content[k, ly, 0], content[k, ly, 1]
        if spans[k, y, 1] > spans[k, y, 0]:
            first = min(first, int(cols[spans[k, y, 0], 0]))
            last = max(last, int(cols[spans[k, y, 1] - 1, 0]))
        new_lo, new_hi = hr_w, 0
        # the HR pixels whose nearest LR sample is lx (columns runs[lx] .. runs[lx + 1] - 1) share its slab's
        # motion and box, so the history's rows and their weights are found once per run
        for lx in range(first, last + 1):
            if lx < content[k, ly, 0] or lx > content[k, ly, 1] or info[k, ly, lx, 10] == 0.0:
                # the slab shows nothing around here (``info`` holds nothing outside ``content``): an empty history
                for x in range(runs[lx], runs[lx + 1]):
                    if shown[k, y, x]:  # else the buffer holds zeros there already
                        for c in range(5):
                            new_history[k, y, x, c] = 0.0
                        shown[k, y, x] = 0
                continue
            new_lo, new_hi = min(new_lo, runs[lx]), max(new_hi, runs[lx + 1])
            mx = scale * info[k, ly, lx, 8]
            sy = y + scale * info[k, ly, lx, 9]
            rows_in = has_history and -0.5 < sy < hr_h - 0.5
            sy = min(max(sy, 0.0), hr_h - 1.0)
            iy = min(int(sy), hr_h - 2) if hr_h > 1 else 0
            iy1 = min(iy + 1, hr_h - 1)
            ty = np.float32(sy - iy)
            uy = one - ty
            # along the run the history is fetched at one fraction past consecutive columns (x + floor(mx)), so each
            # pixel's right column, blended between the two rows, is the next pixel's left one; only where a fetch
            # reaches the history's edge, at either end of the run, is it clamped per pixel
            shift = int(math.floor(mx))
            tx = np.float32(mx - shift)
            ux = one - tx
            carried = False  # whether (q0 .. q4) holds history column x + shift, blended between the rows
            q0 = q1 = q2 = q3 = q4 = zero
            for x in range(runs[lx], runs[lx + 1]):
                x0 = int(cols[x, 1])
                x1 = int(cols[x, 2])
                gx0, gx1, fx = cols[x, 3], cols[x, 4], cols[x, 5]
                va = row_weight * (gx0 + gx1)
                if va < SPLAT_FLOOR:  # the nearest sample alone (:func:`~volsr_core.temporal.stages.splat_weights`)
                    v00, v01, v10, v11, va, vinv = _splat_weights(wy0, wy1, gx0, gx1, dy0, fx, tent)
                    w00, w01, w10, w11, inv = (np.float32(v00), np.float32(v01), np.float32(v10), np.float32(v11),
                                               np.float32(vinv))
                    e0 = _taps(slabs, k, y0, y1, x0, x1, 0, w00, w01, w10, w11) * inv
                    e1 = _taps(slabs, k, y0, y1, x0, x1, 1, w00, w01, w10, w11) * inv
                    e2 = _taps(slabs, k, y0, y1, x0, x1, 2, w00, w01, w10, w11) * inv
                    e3 = _taps(slabs, k, y0, y1, x0, x1, 3, w00, w01, w10, w11) * inv
                else:  # the Gaussian, normalised, blended with the bilinear weights by ``tent``
                    keep = np.float32((1.0 - tent) / va)
                    c0, c1 = np.float32(gx0) * keep, np.float32(gx1) * keep
                    e0 = c0 * splat_rows[x0, 0] + c1 * splat_rows[x1, 0]
                    e1 = c0 * splat_rows[x0, 1] + c1 * splat_rows[x1, 1]
                    e2 = c0 * splat_rows[x0, 2] + c1 * splat_rows[x1, 2]
                    e3 = c0 * splat_rows[x0, 3] + c1 * splat_rows[x1, 3]
                    if tent > 0.0:
                        t0, t1 = np.float32(tent * (1.0 - fx)), np.float32(tent * fx)
                        e0 += t0 * splat_rows[x0, 4] + t1 * splat_rows[x1, 4]
                        e1 += t0 * splat_rows[x0, 5] + t1 * splat_rows[x1, 5]
                        e2 += t0 * splat_rows[x0, 6] + t1 * splat_rows[x1, 6]
                        e3 += t0 * splat_rows[x0, 7] + t1 * splat_rows[x1, 7]
                a = np.float32(va)
                n = zero
                h0 = h1 = h2 = h3 = zero
                ix = x + shift
                if rows_in and 0 <= ix < hr_w - 1:
                    if not carried:
                        q0, q1, q2, q3, q4 = _history_column(history, k, iy, iy1, ix, uy, ty)
                    p0, p1, p2, p3, p4 = _history_column(history, k, iy, iy1, ix + 1, uy, ty)
                    n = min(ux * q4 + tx * p4, cap32)
                    h0, h1, h2, h3 = ux * q0 + tx * p0, ux * q1 + tx * p1, ux * q2 + tx * p2, ux * q3 + tx * p3
                    q0, q1, q2, q3, q4 = p0, p1, p2, p3, p4
                    carried = True
                elif rows_in and -0.5 < x + mx < hr_w - 0.5:
                    sx = min(max(x + mx, 0.0), hr_w - 1.0)
                    ix = min(int(sx), hr_w - 2) if hr_w > 1 else 0
                    ix1 = min(ix + 1, hr_w - 1)
                    ex = np.float32(sx - ix)
                    b00, b01, b10, b11 = (one - ex) * uy, ex * uy, (one - ex) * ty, ex * ty
                    n = min(_taps(history, k, iy, iy1, ix, ix1, 4, b00, b01, b10, b11), cap32)
                    h0 = _taps(history, k, iy, iy1, ix, ix1, 0, b00, b01, b10, b11)
                    h1 = _taps(history, k, iy, iy1, ix, ix1, 1, b00, b01, b10, b11)
                    h2 = _taps(history, k, iy, iy1, ix, ix1, 2, b00, b01, b10, b11)
                    h3 = _taps(history, k, iy, iy1, ix, ix1, 3, b00, b01, b10, b11)
                if n > zero:
                    if rectify:
                        h0 = min(max(h0, info[k, ly, lx, 0]), info[k, ly, lx, 4])
                        h1 = min(max(h1, info[k, ly, lx, 1]), info[k, ly, lx, 5])
                        h2 = min(max(h2, info[k, ly, lx, 2]), info[k, ly, lx, 6])
                        h3 = min(max(h3, info[k, ly, lx, 3]), info[k, ly, lx, 7])
                    share = one / (n + a)
                    e0, e1 = (n * h0 + a * e0) * share, (n * h1 + a * e1) * share
                    e2, e3 = (n * h2 + a * e2) * share, (n * h3 + a * e3) * share
                behind = one - acc[x, 3]
                new_history[k, y, x, 0], new_history[k, y, x, 1] = e0, e1
                new_history[k, y, x, 2], new_history[k, y, x, 3] = e2, e3
                new_history[k, y, x, 4] = min(n + a, cap32)
                acc[x, 0] += behind * e0
                acc[x, 1] += behind * e1
                acc[x, 2] += behind * e2
                acc[x, 3] += behind * e3
                shown[k, y, x] = 1
        spans[k, y, 0], spans[k, y, 1] = (new_lo, new_hi) if new_hi > new_lo else (0, 0)
    b0, b1, b2 = background[0], background[1], background[2]
    drawn_lo = min(drawn_lo, drawn_hi)
    for x in range(drawn_lo):
        out[y, x, 0], out[y, x, 1], out[y, x, 2] = b0, b1, b2
    for x in range(drawn_lo, drawn_hi):
        behind = one - acc[x, 3]
        out[y, x, 0] = acc[x, 0] + behind * b0
        out[y, x, 1] = acc[x, 1] + behind * b1
        out[y, x, 2] = acc[x, 2] + behind * b2
    for x in range(max(drawn_hi, drawn_lo), hr_w):
        out[y, x, 0], out[y, x, 1], out[y, x, 2] = b0, b1, b2


def _prepass_kernel(sources: str):
    """The prepass; a closure over ``sources``, the digest of the layout module whose constants it compiles in
    (:func:`~volsr_core.hashing.sources_sha256`), so that numba's disk cache compiles it anew when that changes."""

    @numba.njit(parallel=True, **_NB)
    def prepass(slabs, box, across, info, content):
        """Per slab and LR pixel of ``slabs`` (K, h, w, SLAB_CHANNELS): the 3x3 neighbourhood's RGBA min/max, the
        motion vector the HR pixels nearest it take (its own where its slab shows something, else that of the most
        opaque neighbour, the first in row order among equals) and whether any of the nine shows something, into
        ``info`` (K, h, w, _INFO); the min/max only with ``box`` (a frame that rectifies: 0.47 against 0.27 ms for
        two 128² slabs); separably (:func:`_widen`): three pixels of each row first (into the work buffer ``across``,
        of ``info``'s shape), then three rows of those, then each pixel's own motion where it shows. Only where the
        3x3 shows something, and the columns of each row that lie there, first and last, into ``content`` (K, h, 2;
        (w, -1) for a row without): ``info`` elsewhere is left as it was (the background around a volume, most of a
        frame's pixels, takes no work)."""
        sources  # noqa: B018 - it keys numba's disk cache on the layout module (hashing.sources_sha256)
        n_slabs, h, w = slabs.shape[0], slabs.shape[1], slabs.shape[2]
        shows = np.empty((n_slabs, h, 2), dtype=np.int64)  # per slab and row: first and last column that shows
        for j in numba.prange(h):
            for k in range(n_slabs):
                shows[k, j, 0], shows[k, j, 1] = w, -1
                for i in range(w):
                    if slabs[k, j, i, SLAB_RGBA + 3] > _EMPTY:
                        shows[k, j, 0], shows[k, j, 1] = min(shows[k, j, 0], i), i
        # the rows' pass where the columns' pass will read it, two rows around the samples that show
        _widen(slabs, SLAB_RGBA, SLAB_RGBA, SLAB_RGBA + 3, SLAB_MOTION, False, box, shows, 2, across)
        _widen(across, 0, 4, 10, 8, True, box, shows, 1, info)
        for j in numba.prange(h):
            for k in range(n_slabs):
                first, last = _reach(shows, k, j, 1, w)
                content[k, j, 0], content[k, j, 1] = first, last
                for i in range(first, last + 1):
                    if slabs[k, j, i, SLAB_RGBA + 3] > _EMPTY:
                        info[k, j, i, 8] = slabs[k, j, i, SLAB_MOTION]
                        info[k, j, i, 9] = slabs[k, j, i, SLAB_MOTION + 1]
                    info[k, j, i, 10] = 1.0 if info[k, j, i, 10] > _EMPTY else 0.0

    return prepass


def _row_kernel(sources: str):
    """The kernel over rows; a closure over ``sources``, the digest of the stage module it compiles in
    (:func:`~volsr_core.hashing.sources_sha256`), so that numba's disk cache compiles it anew when that changes."""

    @numba.njit(parallel=True, **_NB)
    def kernel(history, has_history, slabs, info, content, cols, runs, scale, jy, inv2s2, tent, cap, rectify,
               background, out, new_history, shown, spans):
        sources  # noqa: B018 - it keys numba's disk cache on the stage module (hashing.sources_sha256)
        for y in numba.prange(out.shape[0]):
            acc = np.empty((out.shape[1], 4), dtype=np.float32)
            splat_rows = np.empty((slabs.shape[2], 8), dtype=np.float32)
            _row(y, history, has_history, slabs, info, content, cols, runs, scale, jy, inv2s2, tent, cap, rectify,
                 background, out, new_history, shown, spans, acc, splat_rows)

    return kernel


_prepass = _prepass_kernel(sources_sha256(layout))
_kernel = _row_kernel(sources_sha256(stages))


class LayeredUpsampler(TemporalUpsampler):
    """Temporal upsampling of jittered LR frames cut into depth slabs, one history per slab (one call per frame).

    The constructor is :class:`~volsr_core.temporal.taau.TemporalUpsampler`'s, with ``sigma`` 0.25 LR px,
    ``cap_angle`` 0.3 degrees and ``smooth_count`` 0.5 by default (measured: docs/temporal.md, "Layered history"
    and "A shorter history"; where frames sample finely the cap falls by half, not to a quarter, which keeps it
    where it was before the shorter cap: 0.26 against 0.25 at 4x and 2°); the number of slabs is the frames' own
    (``RayCaster.render(..., slabs=K)``). ``clamp_rotating`` says where the history is clamped into its slab's 3x3
    box while the view rotates, as it always is under a pan or a zoom: ``"fine"`` (the default) where the frame
    samples the volume finely (:meth:`smoothing` above 0: the frames of a 1024² view of a 256-voxel volume, not
    those of a 512² one), ``"always"`` or ``"never"``.
    """

    def __init__(self, scale: int, *, sigma: float = 0.25, cap_angle: float = 0.3, smooth_count: float = 0.5,
                 clamp_rotating: str = "fine", **settings):
        super().__init__(scale, sigma=sigma, cap_angle=cap_angle, smooth_count=smooth_count, side_outputs=False,
                         **settings)
        if clamp_rotating not in CLAMP_ROTATING:
            raise ValueError(f"clamp_rotating must be one of {CLAMP_ROTATING}, got {clamp_rotating!r}")
        self.clamp_rotating = clamp_rotating
        self._info: np.ndarray | None = None  # the prepass's results, its work buffer and where it wrote them
        self._across: np.ndarray | None = None
        self._content: np.ndarray | None = None
        # per history buffer, where it may hold something other than zeros (a slab's pixels shown there): (K, H, W)
        # uint8, 1 there, and (K, H, 2) int64, per slab and row the span of columns they lie in; so a pixel that stays
        # empty is not written again, and a row's columns outside the span and the slab's LR content are not visited
        self._history_shown: tuple[np.ndarray, np.ndarray] | None = None
        self._spare_shown: tuple[np.ndarray, np.ndarray] | None = None

    def _rectifies(self, static: bool, still: bool, pixels_per_voxel: float | None) -> bool:
        """Whether this frame clamps the history (step 4 of the module docstring): under a pan or a zoom, and while the
        view rotates as ``clamp_rotating`` says (``pixels_per_voxel``: the LR frame's, None when unknown); never when
        nothing moves."""
        if static:
            return False
        if still or self.clamp_rotating == "always":
            return True
        return self.clamp_rotating == "fine" and self.smoothing(pixels_per_voxel) > 0.0

    def __call__(self, lr_slabs: np.ndarray, jitter: tuple[float, float], background=(0.0, 0.0, 0.0),
                 rotation: float | None = None, pixels_per_voxel: float | None = None, *,
                 out: np.ndarray | None = None) -> np.ndarray:
        """Accumulate one LR frame given as its depth slabs; returns a new (h * scale, w * scale, 3) float32 image, or
        ``out`` written with it (as :meth:`TemporalUpsampler.__call__`).

        ``lr_slabs`` (K, h, w, SLAB_CHANNELS): :attr:`~volsr_core.render.features.FeatureFrame.slabs`, nearest
        first, motion in LR pixels; ``jitter`` (jx, jy) in [-0.5, 0.5); ``background`` the RGB the slabs are
        composited over (the ray caster's); ``rotation`` and ``pixels_per_voxel`` as
        :meth:`TemporalUpsampler.__call__` takes them. A change in K or size starts a new history.
        """
        slabs = np.asarray(lr_slabs, dtype=np.float32)
        if slabs.ndim != 4 or slabs.shape[3] != SLAB_CHANNELS or slabs.shape[0] < 1:
            raise ValueError(f"expected slabs (K, h, w, {SLAB_CHANNELS}), got {np.shape(lr_slabs)}")
        jx, jy = checked_jitter(jitter)
        n_slabs, h, w = slabs.shape[:3]
        s = self.scale
        shape = (n_slabs, h * s, w * s, 5)  # per slab: premultiplied RGBA, accumulated weight
        has = self.history is not None and self.history.shape == shape
        history = self.history if has else np.zeros((1, 1, 1, 5), dtype=np.float32)
        motion = slabs.reshape(n_slabs * h, w, SLAB_CHANNELS)[..., SLAB_MOTION:SLAB_MOTION + 2]
        static, still, sigma, cap, tent = self._frame_settings(lambda: _moves(motion, 1e-3), has, rotation,
                                                               pixels_per_voxel)
        rectify = self._rectifies(static, still, pixels_per_voxel)
        cols, runs = self._columns(w, jx, sigma)
        if self._info is None or self._info.shape[:3] != (n_slabs, h, w):
            self._info = np.empty((n_slabs, h, w, _INFO), dtype=np.float32)
            self._across = np.empty_like(self._info)
            self._content = np.empty((n_slabs, h, 2), dtype=np.int64)
        _prepass(slabs, rectify, self._across, self._info, self._content)
        if self._spare is not None and self._spare.shape == shape:
            new_history, shown, spans = self._spare, *self._spare_shown
        else:  # zeros: an empty slab's pixels need no writing
            new_history, shown = np.zeros(shape, dtype=np.float32), np.zeros(shape[:3], dtype=np.uint8)
            spans = np.zeros(shape[:2] + (2,), dtype=np.int64)
        out = output_image(out, (h * s, w * s))
        _kernel(history, has, slabs, self._info, self._content, cols, runs, s, jy, 1.0 / (2.0 * sigma * sigma), tent,
                cap, rectify, np.asarray(background, dtype=np.float32), out, new_history, shown, spans)
        self._spare, self._spare_shown = (self.history, self._history_shown) if has else (None, None)
        self.history, self._history_shown = new_history, (shown, spans)
        return out

    def background_window(self) -> tuple[int, int, int, int] | None:
        """The HR window (top, bottom, left, right) outside which the last estimate is the background itself: the LR
        columns where a slab's 3x3 neighbourhood shows something, per row (the prepass's ``content``), widened by one
        LR pixel (the HR pixels a jittered sample is nearest to); (0, 0, 0, 0) where nothing shows; None before a
        frame."""
        if self._content is None:
            return None
        content = self._content
        shown = np.stack([content[:, :, 0].min(axis=0), content[:, :, 1].max(axis=0)], axis=-1)
        return window_of(shown, self.scale, self._info.shape[2], reach=1)
