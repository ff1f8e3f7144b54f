"""The learned base filter of variant XS on the CPU: numba kernels on (H, W, 3) images.

A VolSR model whose network is only its base filter (:class:`~volsr_core.sr.network.BaseFilter`,
variant XS) is one depthwise k x k convolution of the base clipped to [0, 1], edge pixels repeated
past the border, or a pair of them, each pixel taking the one its local orientation picks
(:func:`~volsr_core.sr.network.second_orientation`, the same stages here). :func:`filter_image` does it
on images laid out as TAAU makes them, so the upscaler needs no network inputs and no transposes for
it: a thread takes a band of :data:`BAND_ROWS` rows, lays its clipped, padded channels apart and sums each
pixel's taps row by row (the tap count compiled in, so the taps unroll and the pixels vectorise; a pair finds
each row's orientations from the same band, sums both filters in the same pass and blends) and interleaves the
result; where every tap of a pixel reads one colour (the background either side of a volume: 65-85% of a bench
frame's pixels) the sum is one constant per row end and channel, computed once. Told the window outside which the
image is one colour (``filter_image(..., window=)``: the upscaler passes the one its TAAU reports), the kernels run on
that window alone, read in place, and the rest of the output takes what the filter makes of that colour (the
upscaler's step for XS 0.83-0.91 of its time at 1024², 0.89-1.03 at 512², ``benchmarks/bench_upscaler.py``). Work
buffers stay in a :class:`Scratch` between frames. On TAAU's 512² estimates (2 cores, medians,
``benchmarks/bench_base_filter.py``):
1.6 ms for the 5x5 pair of XS 2x and for a 9x9 filter (XS 4x's until 2026-11-25, now 5x5: 1.1 ms;
docs/network.md), where onnxruntime's depthwise Conv took 2.4 (5x5) and 10.8 ms (9x9), on a faster machine,
without its transposes; the bands and the constant ends took 0.76-0.90 of the time of whole-image passes for one
filter and 0.84-1.01 for a pair (512² and 1024², CT_AVM and MR_Gd, ``--against`` the commit before them). The weights
travel in the ONNX file's metadata (:data:`FILTER_KEY`, written by
:func:`~volsr_core.runtime.export.export_onnx`); the graph stays the reference the kernel is tested against.
"""
from __future__ import annotations

import functools
import json
import math
from pathlib import Path
from typing import Callable

import numba
import numpy as np

from volsr_core.errors import InputError
from volsr_core.sr.network_config import ORIENTATION_LUMA, ORIENTATION_SMOOTHING
from volsr_core.temporal.resample import _across_planes_doubled, _axis_taps, _doubling_weights, _mix_rows

FILTER_KEY = "volsr.base_filter"  # ONNX metadata: {"weights": (3, k, k) or (2, 3, k, k) nested lists, "bias": 3 or 2x3}
LUMA = np.asarray(ORIENTATION_LUMA, dtype=np.float32)
SMOOTHING = np.asarray(ORIENTATION_SMOOTHING, dtype=np.float32)


class Scratch:
    """Work buffers :func:`filter_image` keeps between calls on frames of one size: fresh multi-MB arrays
    every frame cost page faults (about as much as the filter itself at 512²). One per caller (not shared
    between threads)."""

    def __init__(self) -> None:
        self._buffers: dict[str, np.ndarray] = {}
        self.patterns: dict[tuple, np.ndarray] = {}  # :func:`filter_image`'s output around a window, by colour

    def get(self, name: str, shape: tuple[int, ...], dtype: type = np.float32) -> np.ndarray:
        """The C-contiguous buffer ``name`` of ``shape`` (contents undefined): a view of one kept array, made anew only
        when it is too small (or of another dtype), so that every size up to the largest asked shares it (a window
        whose size changes every frame makes no new arrays)."""
        size = math.prod(shape)
        buffer = self._buffers.get(name)
        if buffer is None or buffer.size < size or buffer.dtype != np.dtype(dtype):
            buffer = self._buffers[name] = np.empty(size, dtype)
        return buffer[:size].reshape(shape)


BAND_ROWS = 32
"""Output rows a thread filters from one band of padded planes: a band's planes, luma and sums stay in the core's
L2 at 1024² wide (about 1 MB), where whole-image planes went to memory between the passes (one 5x5 filter on random
images, 16 to 64 rows alike: 0.62-0.90 of the time at 1024² in two runs, 0.82 at 512²)."""
_NB = dict(fastmath=True, error_model="numpy", boundscheck=False, cache=True)
_FLOAT32_MAX = np.finfo(np.float32).max
_NO_PHASES = _doubling_weights(1, 3, True, -0.5)  # an unstretched call's (read-only, empty) doubling weights


@numba.njit(**_NB)
def _fill_band(image: np.ndarray, top: int, left: int, height: int, width: int, first: int, pad: int,
               planes: np.ndarray, rows: int) -> None:
    """The first ``rows`` rows of a band's ``planes`` (3, >= rows, ``width`` + 2 ``pad``): RGB rows ``first`` + j of
    the window of ``image`` (``height`` x ``width`` pixels from (``top``, ``left``); edge rows repeated past it),
    clipped to [0, 1], channels apart, ``pad`` edge pixels repeated each side; each image row read once, pixel by
    pixel (a pass per channel reading every third float made XS 4x's filter take 1.2 times as long,
    ``benchmarks/bench_base_filter.py``)."""
    zero, one = np.float32(0.0), np.float32(1.0)
    for j in range(rows):
        source = image[top + min(max(first + j, 0), height - 1)].reshape(image.shape[1] * 3)[3 * left:]
        red, green, blue = planes[0, j, pad:], planes[1, j, pad:], planes[2, j, pad:]
        for x in range(width):
            red[x] = min(max(source[3 * x], zero), one)
            green[x] = min(max(source[3 * x + 1], zero), one)
            blue[x] = min(max(source[3 * x + 2], zero), one)
        for c in range(3):
            row = planes[c, j]
            first_value, last_value = row[pad], row[pad + width - 1]
            for x in range(pad):
                row[x], row[width + pad + x] = first_value, last_value


@numba.njit(**_NB)
def _flat_ends(planes: np.ndarray, rows: int, ends: np.ndarray) -> None:
    """Per row j < ``rows`` of a band's ``planes`` (C, >= rows, PW): ``ends[j, 0]`` the count of its leading columns
    equal, in every channel, to its first; ``ends[j, 1]`` the first column of its trailing run equal to its last
    (the background either side of a volume, mostly). Found as a least and a greatest index over the whole row, a
    reduction that vectorises (0.2 against 0.7 ms for 512² by scanning in from the ends column by column)."""
    channels, width = planes.shape[0], planes.shape[2]
    for j in range(rows):
        first_differing, last_differing = width, -1
        for c in range(channels):
            row = planes[c, j]
            left, right = row[0], row[width - 1]
            for x in range(width):
                first_differing = min(first_differing, x if row[x] != left else width)
                last_differing = max(last_differing, x if row[x] != right else -1)
        ends[j, 0], ends[j, 1] = first_differing, last_differing + 1


@numba.njit(**_NB)
def _sums_needed(planes: np.ndarray, ends: np.ndarray, j0: int, taps: int, width: int) -> tuple[int, int]:
    """Output columns [start, stop) of the row whose taps read band rows ``j0`` .. ``j0 + taps - 1`` (``ends`` from
    :func:`_flat_ends`) that need their sums: left of ``start`` every tap reads the colour of row ``j0``'s first
    column, from ``stop`` on that of its last, so each of those pixels is one constant per channel."""
    last = planes.shape[2] - 1
    left, right = last + 1, 0
    for j in range(j0, j0 + taps):
        left, right = min(left, ends[j, 0]), max(right, ends[j, 1])
        if not _same_rows(planes, j, j0, 0):
            left = 0
        if not _same_rows(planes, j, j0, last):
            right = last + 1
    start = min(max(left - taps + 1, 0), width)
    return start, max(min(right, width), start)


@numba.njit(**_NB)
def _same_rows(planes: np.ndarray, j: int, j_other: int, x: int) -> bool:
    """Whether rows ``j`` and ``j_other`` of ``planes`` (C, rows, PW) hold the same colour in column ``x``."""
    for c in range(planes.shape[0]):
        if planes[c, j, x] != planes[c, j_other, x]:
            return False
    return True


@numba.njit(**_NB)
def _constant_sum(weights: np.ndarray, bias: np.ndarray, m: int, c: int, value: np.float32) -> np.float32:
    """Filter ``m`` of channel ``c`` (``weights`` (n, C, k, k), ``bias`` (n, C)) on a patch of one ``value``, summed in
    the kernels' order."""
    total = bias[m, c]
    for dy in range(weights.shape[2]):
        for dx in range(weights.shape[3]):
            total += weights[m, c, dy, dx] * value
    return total


@numba.njit(**_NB)
def _band_orientation(planes: np.ndarray, y0: int, y1: int, height: int, halo: int, pad: int,
                      luma_weights: np.ndarray, smoothing: np.ndarray, luma: np.ndarray, across: np.ndarray,
                      product: np.ndarray) -> None:
    """For output rows ``y0`` .. ``y1`` - 1 of an image ``height`` rows tall, the stages of
    :func:`~volsr_core.sr.network.second_orientation` up to the vertical smoothing, from a band's ``planes``
    (:func:`_fill_band` from row ``y0 - halo``, ``halo`` >= r + 1 for ``smoothing``'s radius r): ``luma`` of
    the planes' rows, and in ``across`` row i the product of central differences of image row clamp(y0 - r + i),
    smoothed along x (edge values repeated); ``product`` is a work row of W + 2r. The vertical smoothing reads
    ``across`` rows y - y0 .. y - y0 + 2r for row y (rows past the image repeat its edge rows, as the network)."""
    r = smoothing.shape[0] // 2
    padded_width = planes.shape[2]
    width = padded_width - 2 * pad
    used = y1 - y0 + 2 * halo
    for j in range(used):
        row = luma[j]
        row[:] = luma_weights[0] * planes[0, j]
        for c in range(1, planes.shape[0]):
            weight, source = luma_weights[c], planes[c, j]
            for x in range(padded_width):
                row[x] += weight * source[x]
    for i in range(y1 - y0 + 2 * r):
        j = min(max(y0 - r + i, 0), height - 1) - y0 + halo  # that image row's row in the band
        here, up, down = luma[j], luma[j - 1], luma[j + 1]
        for x in range(width):
            product[x + r] = (np.float32(0.5) * (here[x + pad + 1] - here[x + pad - 1]) * np.float32(0.5)
                              * (down[x + pad] - up[x + pad]))
        for k in range(r):
            product[k], product[width + r + k] = product[r], product[width + r - 1]
        out = across[i]
        out[:width] = np.float32(0.0)
        for k in range(smoothing.shape[0]):
            tap = smoothing[k]
            for x in range(width):
                out[x] += tap * product[x + k]


@numba.njit(**_NB)
def _interleaved(planes: np.ndarray, low: np.float32, high: np.float32, out: np.ndarray) -> None:
    """An RGB row ``out`` (W, 3) from its channels apart, ``planes`` (>= 3, >= W), clamped to [``low``, ``high``]: pixel
    by pixel, each written whole (a pass per channel writing every third float made XS 4x's filter take 1.1-1.2 times
    as long, ``benchmarks/bench_base_filter.py``)."""
    flat = out.reshape(out.shape[0] * 3)
    red, green, blue = planes[0], planes[1], planes[2]
    for x in range(out.shape[0]):
        flat[3 * x] = min(max(red[x], low), high)
        flat[3 * x + 1] = min(max(green[x], low), high)
        flat[3 * x + 2] = min(max(blue[x], low), high)


@functools.lru_cache(maxsize=None)
def _filter_bands(taps: int, doubled: bool) -> Callable:
    """The kernel for one filter of ``taps`` x ``taps`` (compiled once per size and ``doubled``, cached on disk):
    ``bands(image, top, left, height, width, weights, bias, low, high, planes, ends, total, lines, phase_w, out,
    out_top, out_left)`` fills ``out`` from the window of ``image`` (H, W, C) ``height`` x ``width`` pixels from
    (``top``, ``left``) through ``weights`` (1, C, k, k) and ``bias`` (1, C), :data:`BAND_ROWS` rows per band
    (``planes`` (bands, C, BAND_ROWS + k - 1, W + k - 1), ``ends`` (bands, BAND_ROWS + k - 1, 2) int64 and ``total``
    (bands, C, W) its work buffers): the band's clipped, padded planes (:func:`_fill_band`) and their rows' flat ends
    (:func:`_flat_ends`), then per row and channel, per tap row, each pixel's ``taps`` products summed in registers
    into a row accumulator (the tap count a compile-time constant, so the taps unroll and the pixels vectorise:
    1.7 times as fast at 9 taps as a pass per tap over the row) between the row's flat ends
    (:func:`_sums_needed`; one constant each side), then the row's channels clamped to [``low``, ``high``] and
    interleaved into ``out`` (:func:`_interleaved`), the window's row y into row ``out_top`` + y from column
    ``out_left`` on.
    ``doubled``: each row goes into the band's row of ``lines`` (bands, C, W), channels apart, instead and is written
    to ``out`` (H, 2W, C) doubled in width by the resampling's first stage (``_across_planes_doubled`` with
    ``phase_w``): the first pass of the filter and a 2x stretch in one (:func:`filter_image`)."""
    pad = taps // 2

    @numba.njit(parallel=True, **_NB)
    def bands(image, top, left, height, width, weights, bias, low, high, planes, ends, total, lines, phase_w, out,
              out_top, out_left):
        channels = image.shape[2]
        last = planes.shape[3] - 1
        for b in numba.prange(planes.shape[0]):
            y0 = b * BAND_ROWS
            y1 = min(y0 + BAND_ROWS, height)
            band, row_total, line = planes[b], total[b], lines[b]
            _fill_band(image, top, left, height, width, y0 - pad, pad, band, y1 - y0 + 2 * pad)
            _flat_ends(band, y1 - y0 + 2 * pad, ends[b])
            for y in range(y0, y1):
                start, stop = _sums_needed(band, ends[b], y - y0, taps, width)
                for c in range(channels):
                    # views from ``start``: indices that cannot be negative need no wraparound, so the loop
                    # vectorises (over range(start, stop) it did not: 5 times the time)
                    summed = row_total[c, start:stop]
                    summed[:] = bias[0, c]
                    for dy in range(taps):
                        source = band[c, y - y0 + dy, start:]
                        row = weights[0, c, dy]
                        for x in range(stop - start):
                            value = summed[x]
                            for dx in range(taps):
                                value += row[dx] * source[x + dx]
                            summed[x] = value
                    row_total[c, :start] = _constant_sum(weights, bias, 0, c, band[c, y - y0, 0])
                    row_total[c, stop:] = _constant_sum(weights, bias, 0, c, band[c, y - y0, last])
                    if doubled:
                        for x in range(width):
                            line[c, x] = min(max(row_total[c, x], low), high)
                if doubled:
                    _across_planes_doubled(line, phase_w, out[y].reshape(out.shape[1] * out.shape[2]))
                else:
                    _interleaved(row_total, low, high, out[out_top + y][out_left:out_left + width])

    return bands


@functools.lru_cache(maxsize=None)
def _filter_bands_pair(taps: int, doubled: bool) -> Callable:
    """:func:`_filter_bands` for a pair (``bands(image, top, left, height, width, weights, bias, luma_weights,
    smoothing, low, high, planes, ends, luma, across, work, lines, phase_w, out, out_top, out_left)``, ``weights``
    (2, C, k, k), ``bias`` (2, C), the window, ``lines``, ``phase_w``, ``out`` and its offsets and ``doubled`` as
    there; per band, ``planes`` (C, BAND_ROWS + 2 * halo, W + k - 1) with W the window's width, halo =
    max(k // 2, r + 1) for ``smoothing``'s radius r, ``ends`` of its rows, ``luma`` of the planes' rows, ``across``
    (BAND_ROWS + 2r, W) and ``work`` (2 + 2C, W + 2r): a row of the orientation's products, the C channels' sums
    of the first filter, of the second, and the pick): the band's orientation stages (:func:`_band_orientation`), then
    per row the vertical smoothing's sign, and both filters summed in the same pass (one load, two products) between
    the row's flat ends, each pixel taking filter ``second`` by a blend with weight 0 or 1 (no branch, so it
    vectorises too)."""
    pad = taps // 2

    @numba.njit(parallel=True, **_NB)
    def bands(image, top, left, height, width, weights, bias, luma_weights, smoothing, low, high, planes, ends, luma,
              across, work, lines, phase_w, out, out_top, out_left):
        channels = image.shape[2]
        r = smoothing.shape[0] // 2
        halo = max(pad, r + 1)
        last = planes.shape[3] - 1
        for b in numba.prange(planes.shape[0]):
            y0 = b * BAND_ROWS
            y1 = min(y0 + BAND_ROWS, height)
            band, line = planes[b], lines[b]
            # per channel its first filter's and its second's sums, then which one each pixel takes
            first, other, pick = work[b, 1:1 + channels], work[b, 1 + channels:1 + 2 * channels], work[b, -1]
            _fill_band(image, top, left, height, width, y0 - halo, pad, band, y1 - y0 + 2 * halo)
            _flat_ends(band, y1 - y0 + 2 * halo, ends[b])
            _band_orientation(band, y0, y1, height, halo, pad, luma_weights, smoothing, luma[b], across[b],
                              work[b, 0])
            for y in range(y0, y1):
                pick[:width] = np.float32(0.0)
                for k in range(smoothing.shape[0]):
                    tap, source = smoothing[k], across[b, y - y0 + k]
                    for x in range(width):
                        pick[x] += tap * source[x]
                for x in range(width):
                    pick[x] = np.float32(1.0) if pick[x] < 0 else np.float32(0.0)
                j0 = y - y0 + halo - pad  # the band row of the first tap row
                start, stop = _sums_needed(band, ends[b], j0, taps, width)
                for c in range(channels):
                    mine, mine_other = first[c], other[c]
                    summed, summed_other = mine[start:stop], mine_other[start:stop]  # as in _filter_bands
                    summed[:] = bias[0, c]
                    summed_other[:] = bias[1, c]
                    for dy in range(taps):
                        source = band[c, j0 + dy, start:]
                        row, row_other = weights[0, c, dy], weights[1, c, dy]
                        for x in range(stop - start):
                            value, value_other = summed[x], summed_other[x]
                            for dx in range(taps):
                                tap = source[x + dx]
                                value += row[dx] * tap
                                value_other += row_other[dx] * tap
                            summed[x], summed_other[x] = value, value_other
                    mine[:start] = _constant_sum(weights, bias, 0, c, band[c, j0, 0])
                    mine_other[:start] = _constant_sum(weights, bias, 1, c, band[c, j0, 0])
                    mine[stop:width] = _constant_sum(weights, bias, 0, c, band[c, j0, last])
                    mine_other[stop:width] = _constant_sum(weights, bias, 1, c, band[c, j0, last])
                    for x in range(width):
                        if doubled:
                            line[c, x] = min(max(mine[x] + pick[x] * (mine_other[x] - mine[x]), low), high)
                        else:
                            mine[x] += pick[x] * (mine_other[x] - mine[x])
                if doubled:
                    _across_planes_doubled(line, phase_w, out[y].reshape(out.shape[1] * out.shape[2]))
                else:
                    _interleaved(first, low, high, out[out_top + y][out_left:out_left + width])

    return bands


def filter_reach(weights: np.ndarray, stretch: int = 1) -> int:
    """How far (image pixels) a pixel of :func:`filter_image`'s input reaches into its output: the filter's radius, for
    a pair at least the orientation's (its central differences and smoothing), and the stretch's cubic taps."""
    pad = weights.shape[2] // 2
    reach = pad if weights.shape[0] == 1 else max(pad, SMOOTHING.shape[0] // 2 + 1)
    return reach + (2 if stretch == 2 else 0)


@numba.njit(parallel=True, **_NB)
def _fill_outside(out: np.ndarray, pattern: np.ndarray, top: int, bottom: int, left: int, right: int) -> None:
    """``out`` (H, W, C) outside rows ``top`` .. ``bottom`` - 1 by columns ``left`` .. ``right`` - 1 from ``pattern``
    (s, W * C): row y takes ``pattern[y % s]``, the filtered colour's values by output phase, a row laid out ahead."""
    width = out.shape[1] * out.shape[2]
    flat = out.reshape(out.shape[0], width)
    a, b = left * out.shape[2], right * out.shape[2]
    for y in numba.prange(out.shape[0]):
        row, values = flat[y], pattern[y % pattern.shape[0]]
        if y < top or y >= bottom:
            row[:] = values
        else:
            row[:a] = values[:a]
            row[b:] = values[b:]


def _outside_pattern(colour: np.ndarray, weights: np.ndarray, bias: np.ndarray, clip_output: bool, stretch: int,
                     stretch_a: float, width: int, scratch: Scratch) -> np.ndarray:
    """What :func:`filter_image` makes of an image of one ``colour`` away from its edges, by output phase, laid out
    along an output row ``width`` pixels wide: (stretch, width * 3), row p for the output rows y with y % stretch = p.
    Found once per colour, filter and width on a small image of that colour (the same sums as the whole image's, so
    the same values), kept in ``scratch``."""
    key = (colour.tobytes(), weights.tobytes(), bias.tobytes(), clip_output, stretch, float(stretch_a), width)
    patterns = scratch.patterns
    if key not in patterns:
        if len(patterns) > 16:
            patterns.clear()
        size = 2 * filter_reach(weights, stretch) + 4
        small = filter_image(np.broadcast_to(colour, (size, size, 3)), weights, bias, clip_output=clip_output,
                             stretch=stretch, stretch_a=stretch_a)
        middle = (size // 2) * stretch
        phases = small[middle:middle + stretch, middle:middle + stretch]  # (stretch, stretch, 3)
        patterns[key] = np.ascontiguousarray(np.tile(phases, (1, width // stretch, 1)).reshape(stretch, width * 3))
    return patterns[key]


def filter_image(image: np.ndarray, weights: np.ndarray, bias: np.ndarray,
                 scratch: Scratch | None = None, clip_output: bool = False, stretch: int = 1,
                 stretch_a: float = -0.5, window: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """``image`` (H, W, 3), clipped to [0, 1] and edge-padded, through ``weights`` (n, 3, k, k) and ``bias``
    (n, 3), n = 1 or a pair chosen per pixel by orientation: a new (H, W, 3) float32 image, what the network's
    :class:`~volsr_core.sr.network.BaseFilter` computes (channels first there). ``scratch`` keeps the work
    buffers for the next call (a fresh set each call without it); ``clip_output`` clips the result to [0, 1] in
    the same pass (what a displayed frame needs, without a second pass over it).

    ``stretch`` 2 returns the result stretched to (2H, 2W, 3) by Keys' cubic convolution with ``stretch_a``
    (:func:`~volsr_core.temporal.resample.resize_bicubic`'s values, clipped as the result is): each filtered row is
    doubled in width as the filter's bands make it, then the rows are mixed, so the filtered image is never written
    whole (the stretch of ``Pipeline(..., stretch=2)``).

    ``window`` (top, bottom, left, right; image pixels, bottom and right exclusive), where the caller knows the image
    to be one colour outside it (the background around a volume in a TAAU estimate): the kernels run on the window
    widened by :func:`filter_reach` alone and the rest of the output takes what they make of that colour, found
    once; the same values (the background's sums are the same sums), in the time of the window's pixels."""
    if stretch not in (1, 2):
        raise ValueError(f"the filter's stretch is 1 or 2, got {stretch!r}")
    scratch = Scratch() if scratch is None else scratch
    weights = np.ascontiguousarray(weights, dtype=np.float32)
    bias = np.asarray(bias, dtype=np.float32)
    height, width, channels = np.shape(image)
    top, bottom, left, right = 0, height, 0, width
    if window is not None:
        reach = filter_reach(weights, stretch)
        top, bottom = max(int(window[0]) - reach, 0), min(int(window[1]) + reach, height)
        left, right = max(int(window[2]) - reach, 0), min(int(window[3]) + reach, width)
        if bottom <= top or right <= left:
            top = bottom = left = right = 0
    out = np.empty((stretch * height, stretch * width, channels), np.float32)
    if (top, bottom, left, right) != (0, height, 0, width):  # one colour around the window: a corner pixel's
        corner = image[0, 0] if top > 0 or left > 0 else image[height - 1, width - 1]
        pattern = _outside_pattern(np.asarray(corner, np.float32), weights, bias, clip_output, stretch,
                                   float(stretch_a), stretch * width, scratch)
        _fill_outside(out, pattern, stretch * top, stretch * bottom, stretch * left, stretch * right)
        if bottom <= top:
            return out
    _filter_window(np.ascontiguousarray(image, dtype=np.float32), (top, bottom, left, right), weights, bias, scratch,
                   clip_output, stretch, float(stretch_a), out)
    return out


def _filter_window(image: np.ndarray, window: tuple[int, int, int, int], weights: np.ndarray, bias: np.ndarray,
                   scratch: Scratch, clip_output: bool, stretch: int, stretch_a: float, out: np.ndarray) -> None:
    """:func:`filter_image`'s kernels on the ``window`` (top, bottom, left, right) of the C-contiguous ``image`` (H, W,
    3), read in place, into the same window of ``out`` (scaled by ``stretch``); edge pixels repeated past the window."""
    top, bottom, left, right = window
    height, width, channels = bottom - top, right - left, image.shape[2]
    pad = weights.shape[2] // 2
    n_bands = -(-height // BAND_ROWS)
    doubled = stretch == 2
    # doubled, the bands write their rows doubled in width into ``rows``, and the rows are mixed into ``out`` after
    rows = scratch.get("doubled rows", (height, 2 * width, channels)) if doubled else out
    lines = scratch.get("lines", (n_bands, channels, width) if doubled else (1, 1, 1))
    phase_w = _doubling_weights(width, 2 * width, True, stretch_a) if doubled else _NO_PHASES
    # the kernels clamp as they write ``out``; unclipped, to finite bounds (their fastmath assumes no infinities)
    low, high = (np.float32(0.0), np.float32(1.0)) if clip_output else (-_FLOAT32_MAX, _FLOAT32_MAX)
    band_top, band_left = (0, 0) if doubled else (top, left)  # doubled, the bands write into ``rows``
    if weights.shape[0] > 1:
        r = SMOOTHING.shape[0] // 2
        band_rows = BAND_ROWS + 2 * max(pad, r + 1)
        planes = scratch.get("planes", (n_bands, channels, band_rows, width + 2 * pad))
        luma = scratch.get("luma", (n_bands, band_rows, width + 2 * pad))
        across = scratch.get("across", (n_bands, BAND_ROWS + 2 * r, width))
        work = scratch.get("work", (n_bands, 2 + 2 * channels, width + 2 * r))
        ends = scratch.get("ends", (n_bands, band_rows, 2), np.int64)
        _filter_bands_pair(weights.shape[2], doubled)(image, top, left, height, width, weights, bias, LUMA, SMOOTHING,
                                                      low, high, planes, ends, luma, across, work, lines, phase_w,
                                                      rows, band_top, band_left)
    else:
        planes = scratch.get("planes", (n_bands, channels, BAND_ROWS + 2 * pad, width + 2 * pad))
        total = scratch.get("total", (n_bands, channels, width))
        ends = scratch.get("ends", (n_bands, BAND_ROWS + 2 * pad, 2), np.int64)
        _filter_bands(weights.shape[2], doubled)(image, top, left, height, width, weights, bias, low, high, planes,
                                                 ends, total, lines, phase_w, rows, band_top, band_left)
    if doubled:
        _mix_rows(rows.reshape(height, 2 * width * channels), *_axis_taps(height, 2 * height, True, stretch_a),
                  low, high, out, 2 * top, 2 * left)


def filter_metadata(weights: np.ndarray, bias: np.ndarray) -> str:
    """The :data:`FILTER_KEY` metadata value for ``weights`` (n, 3, k, k) and ``bias`` (n, 3); one filter is
    written (3, k, k) and (3,), as models made before filter pairs hold it."""
    weights, bias = np.asarray(weights, dtype=float), np.asarray(bias, dtype=float)
    if weights.shape[0] == 1:
        weights, bias = weights[0], bias[0]
    return json.dumps({"weights": weights.tolist(), "bias": bias.tolist()})


def read_filter_metadata(text: str, path: Path, kernel: int, orientations: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """``(weights (orientations, 3, kernel, kernel), bias (orientations, 3))`` float32 from a
    :data:`FILTER_KEY` value; a one-line InputError naming ``path`` when it is not that."""
    try:
        mapping = json.loads(text)
        weights = np.asarray(mapping["weights"], dtype=np.float32)
        bias = np.asarray(mapping["bias"], dtype=np.float32)
    except (ValueError, KeyError, TypeError) as err:
        raise InputError(path, f"{FILTER_KEY}: not the filter's weights and bias ({err})") from None
    expected = (3, kernel, kernel) if orientations == 1 else (orientations, 3, kernel, kernel)
    if weights.shape != expected or bias.shape != expected[:-2] or not (np.isfinite(weights).all()
                                                                        and np.isfinite(bias).all()):
        raise InputError(path, f"{FILTER_KEY}: expected finite weights of shape {expected} and biases of shape "
                         f"{expected[:-2]}, got {weights.shape} and {bias.shape}")
    return weights.reshape(orientations, 3, kernel, kernel), bias.reshape(orientations, 3)
