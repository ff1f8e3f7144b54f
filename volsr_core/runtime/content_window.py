"""Where a frame shows the volume: the window of LR pixels a TAAU-based network has to run on.

Most of a view is background around the volume (of the bench's 512² frames 68-87% of the pixels,
docs/performance-studies.md, "Where the frame is background"). There a TAAU-based network
(``NetworkConfig.taau_base``, no previous frames) sees the same inputs everywhere: the background colour, no
alpha, the far depth, and a base (the TAAU estimate) that is the background; so it adds the same residual
everywhere (about 1e-5 on a black background, up to about 0.02 on a coloured one, which the training videos never
had), and the base alone, the background, is what it should have made there. :func:`content_window` finds the LR
rows and columns where the frame or the base shows something, widened by a margin that covers what the network's
receptive field carries from the window's edge into the content, so that
:class:`~volsr_core.runtime.upscaler.StatefulUpscaler` runs the network on that window alone and takes the base
outside it (measured in docs/performance.md, "The U-Nets on the volume alone").
"""
from __future__ import annotations

import numba
import numpy as np

WINDOW_MARGIN = 8
"""LR pixels the window reaches beyond the content on each side: where the volume shows, the shipped U-Nets' images
on the bench's orbits lie within 0.0043 of those they make on the whole frame (PSNR 84-93 dB against them;
``benchmarks/bench_content_window.py``), where with 1 LR pixel they lay up to 0.016 from them on the test's
phantom (``tests/test_upscaler_window.py``)."""
WINDOW_ALIGN = 4
"""The window's corners lie on multiples of this many LR pixels (or on the frame's edge), so that the U-Nets' two
max-pools tile it as they tile the whole frame."""
NEARBY = 2
"""LR pixels from where the frame's alpha shows something within which the upscaler takes a U-Net's output inside
the window (:func:`shows_nearby`), the TAAU estimate beyond. On the bench's four volumes at 512², 2° (S 2x and S 4x),
the images so made lie within 0.010 of the network's own everywhere, nearer the ground truth where they differ (a
mean error of 0.0000-0.0002 there against 0.0021-0.0041) and 0.000-0.003 dB above them in PSNR; at 1 LR pixel they
lay up to 0.25 from them, taking away what the network fills in beside thin structures that the current frame's
rays miss (0.006 dB lower on CT_AVM)."""
_BLOCK = 64  # HR pixels :func:`_row_extents` tests at once


@numba.njit(inline="always", fastmath=True, boundscheck=False)
def _differs(red, green, blue, start, stop, b0, b1, b2):
    """How many of the pixels start .. stop - 1 of one row's planes differ from (b0, b1, b2): a sum without a branch,
    which the compiler turns into vector instructions."""
    count = 0
    for x in range(start, stop):
        count += (red[x] != b0) | (green[x] != b1) | (blue[x] != b2)
    return count


@numba.njit(parallel=True, cache=True, fastmath=True, boundscheck=False)
def _row_extents(alpha, base, background, scale, extents):
    """Per LR row j of ``alpha`` (h, w), into ``extents`` (h, 2): the first and last LR column where ``alpha`` is
    above 0 or where one of the row's ``scale`` HR rows of ``base`` (>= 3, h * scale, w * scale: RGB planes first)
    differs from ``background`` (3) in an RGB channel; (w, -1) where neither does. The HR rows are read in blocks of
    :data:`_BLOCK` pixels from each end up to the columns known to show."""
    h, w = alpha.shape
    width = base.shape[2]
    b0, b1, b2 = background[0], background[1], background[2]
    for j in numba.prange(h):
        lo, hi = w, -1
        for i in range(w):
            if alpha[j, i] > 0.0:
                lo = min(lo, i)
                hi = i
        for y in range(j * scale, min((j + 1) * scale, base.shape[1])):
            red, green, blue = base[0, y], base[1, y], base[2, y]
            for start in range(0, min(lo * scale, width), _BLOCK):  # from the left up to the first that shows
                stop = min(start + _BLOCK, lo * scale, width)
                if _differs(red, green, blue, start, stop, b0, b1, b2):
                    for x in range(start, stop):
                        if red[x] != b0 or green[x] != b1 or blue[x] != b2:
                            lo = x // scale
                            break
                    break
            for stop in range(width, (hi + 1) * scale, -_BLOCK):  # from the right down to the last
                start = max(stop - _BLOCK, (hi + 1) * scale, 0)
                if _differs(red, green, blue, start, stop, b0, b1, b2):
                    for x in range(stop - 1, start - 1, -1):
                        if red[x] != b0 or green[x] != b1 or blue[x] != b2:
                            hi = x // scale
                            break
                    break
        extents[j, 0], extents[j, 1] = lo, hi


def content_window(alpha: np.ndarray, base: np.ndarray | None, background, scale: int, margin: int = WINDOW_MARGIN,
                   align: int = WINDOW_ALIGN) -> tuple[int, int, int, int]:
    """The LR window (top, bottom, left, right; bottom and right exclusive) holding every LR pixel where ``alpha``
    (h, w: the LR frame's accumulated opacity) is above 0 or ``base`` (C >= 3, h * scale, w * scale: the HR image
    the network refines as planes, RGB first, strided as it comes: an (H, W, C) image's ``transpose(2, 0, 1)`` is read
    in place) differs from ``background`` (RGB), widened by ``margin`` LR pixels
    each way, its corners moved out to multiples of ``align`` and clipped to the frame; (0, 0, 0, 0) where nothing
    shows. ``base`` None: an estimate known to be the background beyond one LR pixel from where ``alpha`` is above 0
    (the layered TAAU's: it composites its slabs only where one shows within a 3x3 LR neighbourhood), which is not
    read; the window reaches one LR pixel further instead."""
    h, w = alpha.shape
    extents = np.empty((h, 2), dtype=np.int64)
    if base is None:
        base, margin = np.zeros((3, 0, 0), dtype=np.float32), margin + 1
    _row_extents(np.ascontiguousarray(alpha, dtype=np.float32), np.asarray(base, dtype=np.float32),
                 np.asarray(background, dtype=np.float32)[:3], int(scale), extents)
    rows = np.flatnonzero(extents[:, 1] >= extents[:, 0])
    if rows.size == 0:
        return 0, 0, 0, 0
    shown = extents[rows]
    top, bottom = rows[0] - margin, rows[-1] + 1 + margin
    left, right = int(shown[:, 0].min()) - margin, int(shown[:, 1].max()) + 1 + margin
    return (max(top // align * align, 0), min(-(-bottom // align) * align, h),
            max(left // align * align, 0), min(-(-right // align) * align, w))


def shows_nearby(alpha: np.ndarray, window: tuple[int, int, int, int], reach: int = NEARBY) -> np.ndarray:
    """Per LR pixel of ``window`` (top, bottom, left, right; bottom and right exclusive) of ``alpha`` (h, w: the LR
    frame's accumulated opacity), bool: whether ``alpha`` is above 0 within ``reach`` LR pixels of it (its 5x5
    neighbourhood at 2), pixels outside the window counted too. Where it is False a TAAU-based network's base is
    what TAAU makes of an empty neighbourhood, the background, and what the network adds there is the residual of a
    background it was never trained on (the shipped S 4x's: up to 0.058 on a light one, 0.010 on black): the
    upscaler keeps the base. Shifted ORs of bytes, a column pass and a row pass: 0.5 ms on a 512² window of a frame's
    alpha (a strided view; 0.2 ms on a contiguous one), where numba loops took 0.9-1.3 ms."""
    top, bottom, left, right = window
    h, w = alpha.shape
    rows, columns = max(bottom - top, 0), max(right - left, 0)
    padded = np.zeros((rows + 2 * reach, columns + 2 * reach), np.bool_)  # the window and reach around it
    y0, y1, x0, x1 = max(top - reach, 0), min(bottom + reach, h), max(left - reach, 0), min(right + reach, w)
    if y1 > y0 and x1 > x0:
        np.greater(alpha[y0:y1, x0:x1], 0.0, out=padded[y0 - top + reach:y1 - top + reach,
                                                        x0 - left + reach:x1 - left + reach])
    near = padded[:rows].copy()
    for dy in range(1, 2 * reach + 1):
        near |= padded[dy:dy + rows]
    out = near[:, :columns].copy()
    for dx in range(1, 2 * reach + 1):
        out |= near[:, dx:dx + columns]
    return out
