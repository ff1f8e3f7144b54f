"""TAAU and the layered TAAU as CUDA kernels (numba-cuda): the CPU kernels' steps, a thread per pixel, on device arrays.

A frame the CUDA ray caster rendered can stay on the device through the temporal upsampling: the histories, the
prepass boxes and the output live there, and only a flag (does anything move?) travels back per frame: 3 kernel
launches, one 4-byte copy back and, without ``out``, one allocation a frame (each call from the host costs a few
hundredths to tenths of a ms there, docs/performance-gpu.md). The per-pixel
maths are the stages of :mod:`volsr_core.temporal.stages`, compiled here for CUDA as the CPU kernels compile them
for the CPU; the steps are those of :class:`~volsr_core.temporal.taau.TemporalUpsampler` and
:class:`~volsr_core.temporal.layered.LayeredUpsampler` (their docstrings), whose settings these classes inherit.
The CPU kernels walk each row in runs of HR pixels sharing their nearest LR sample and slide their Catmull-Rom
sums along a run; here each thread does one pixel's whole sum, in the same order, so the two builds agree to float
rounding (``tests/test_temporal_cuda.py``, in Numba's CUDA simulator without a GPU). TAAU's side outputs
(``last_aux``) are not computed: the device path serves the base-filter models (variant XS), which do not read them.

Importing this module needs ``numba.cuda`` (``pip install 'volsr[cuda]'``); ``NUMBA_ENABLE_CUDASIM=1`` before
numba is imported runs it in the simulator (tiny images only).
"""
from __future__ import annotations

import numpy as np

if not hasattr(np, "row_stack"):  # NumPy >= 2.5 removed it; numba-cuda <= 0.30 still overloads it at import
    np.row_stack = np.vstack

from numba import cuda, float32  # noqa: E402

from volsr_core.render.layout import SLAB_CHANNELS, SLAB_MOTION, SLAB_RGBA  # noqa: E402
from volsr_core.temporal.layered import _EMPTY, _INFO, LayeredUpsampler  # noqa: E402
from volsr_core.temporal.stages import build_temporal_stages  # noqa: E402
from volsr_core.temporal.taau import TemporalUpsampler, checked_jitter  # noqa: E402

_STAGES = build_temporal_stages(cuda.jit(device=True, inline=True))
_to_ycocg32, _sample_window, _splat_weights = _STAGES.to_ycocg32, _STAGES.sample_window, _STAGES.splat_weights
_to_rgb = _STAGES.to_rgb
_catmull_rom_weights, _history_column = _STAGES.catmull_rom_weights, _STAGES.history_column
_mix, _taps, _clamp_to_ycocg_bounds = _STAGES.catmull_rom_mix, _STAGES.bilinear_taps, _STAGES.clamp_to_ycocg_bounds
_nearest_depth, _history_weight = _STAGES.nearest_depth, _STAGES.history_weight

THREADS = (16, 8)
_MOVES_EPS = 1e-3  # a vector with a component of at least this many LR px moves (as the CPU classes test it)


def _blocks(width: int, height: int) -> tuple[int, int]:
    return (width + THREADS[0] - 1) // THREADS[0], (height + THREADS[1] - 1) // THREADS[1]


@cuda.jit
def _flag_motion(motion, first, eps, stamp, flag):
    """``flag[0]`` = ``stamp`` where any vector of ``motion`` (rows, w, C), channels ``first`` and ``first + 1``, has
    a component of at least ``eps``."""
    x, y = cuda.grid(2)
    if y < motion.shape[0] and x < motion.shape[1]:
        if abs(motion[y, x, first]) >= eps or abs(motion[y, x, first + 1]) >= eps:
            flag[0] = stamp


class MotionFlag:
    """Whether any vector of a frame moves, the device's answer to the CPU classes' ``_moves``: one launch and one
    int32 copied back. The flag stays on the device between calls and each call's kernel writes that call's own stamp,
    so it needs no zeroing (an upload of its own, about 0.2 ms on the lent H200) before the next."""

    def __init__(self) -> None:
        self._flag = None
        self._stamp = 0

    def __call__(self, motion, first: int) -> bool:
        """For channels ``first``, ``first + 1`` of device array ``motion`` (rows, w, C)."""
        if self._flag is None:
            self._flag = cuda.to_device(np.zeros(1, dtype=np.int32))
        self._stamp = self._stamp % np.iinfo(np.int32).max + 1  # 1, 2, ...: never the flag's first 0
        _flag_motion[_blocks(motion.shape[1], motion.shape[0]), THREADS](motion, first, _MOVES_EPS, self._stamp,
                                                                         self._flag)
        return int(self._flag.copy_to_host()[0]) == self._stamp


def _device(array, dtype=np.float32):
    """``array`` as a device array: a device array as it is, a host array copied."""
    if hasattr(array, "copy_to_host"):  # a device array (numba's, or the simulator's)
        return array
    return cuda.to_device(np.ascontiguousarray(array, dtype=dtype))


def _output(out, shape: tuple[int, ...]):
    """The (H, W, 3) float32 device array an upsampler writes its estimate into: ``out`` when given (a ValueError
    unless it is a device array of ``shape``), else a new one."""
    if out is None:
        return cuda.device_array(shape, dtype=np.float32)
    if not hasattr(out, "copy_to_host") or tuple(out.shape) != shape or out.dtype != np.float32:
        raise ValueError(f"out must be a float32 device array of shape {shape}, got {type(out).__name__} "
                         f"{getattr(out, 'dtype', None)} {tuple(getattr(out, 'shape', ()))}")
    return out


# -- TAAU ---------------------------------------------------------------------------------------------------------
@cuda.jit
def _taau_prepass(lr, motion, scale, dis_motion, box):
    """LR pixel (i, j): the YCoCg min/max of its 3x3 neighbourhood (edges repeated) into box[j, i, 0:6], and 1 in
    box[j, i, 6] where the neighbourhood's motion spreads more than ``dis_motion`` HR px (parallax)."""
    i, j = cuda.grid(2)
    h, w = lr.shape[0], lr.shape[1]
    if j >= h or i >= w:
        return
    lo0 = lo1 = lo2 = float32(1e30)
    hi0 = hi1 = hi2 = float32(-1e30)
    spread = 0.0
    m0, m1 = motion[j, i, 0], motion[j, i, 1]
    for dy in range(-1, 2):
        yy = min(max(j + dy, 0), h - 1)
        for dx in range(-1, 2):
            xx = min(max(i + dx, 0), w - 1)
            c0, c1, c2 = _to_ycocg32(lr[yy, xx, 0], lr[yy, xx, 1], lr[yy, xx, 2])
            lo0, lo1, lo2 = min(lo0, c0), min(lo1, c1), min(lo2, c2)
            hi0, hi1, hi2 = max(hi0, c0), max(hi1, c1), max(hi2, c2)
            spread = max(spread, abs(motion[yy, xx, 0] - m0) + abs(motion[yy, xx, 1] - m1))
    box[j, i, 0], box[j, i, 1], box[j, i, 2] = lo0, lo1, lo2
    box[j, i, 3], box[j, i, 4], box[j, i, 5] = hi0, hi1, hi2
    box[j, i, 6] = 1.0 if scale * spread > dis_motion else 0.0


@cuda.jit
def _taau_pixels(history, has_history, lr, motion, depth, box, scale, jx, jy, inv2s2, tent, cap, disocclusion,
                 rectify, out, new_history):
    """HR pixel (x, y): TAAU's steps 1-7 (``TemporalUpsampler``)."""
    x, y = cuda.grid(2)
    hr_h, hr_w = out.shape[0], out.shape[1]
    if y >= hr_h or x >= hr_w:
        return
    lr_h, lr_w = lr.shape[0], lr.shape[1]
    ly, y0, y1, dy0, wy0, wy1 = _sample_window(y, scale, jy, lr_h, inv2s2)
    lx, x0, x1, fx, wx0, wx1 = _sample_window(x, scale, jx, lr_w, inv2s2)
    # one colour in the 3x3 box (the background around a volume, mostly): the pixel is that colour (as on the CPU)
    flat = (rectify and box[ly, lx, 0] == box[ly, lx, 3] and box[ly, lx, 1] == box[ly, lx, 4]
            and box[ly, lx, 2] == box[ly, lx, 5])
    # 1. the current estimate: 2x2 Gaussian splat, blended with bilinear weights by ``tent``
    w00, w01, w10, w11, a, inv = _splat_weights(wy0, wy1, wx0, wx1, dy0, fx, tent)
    if flat:
        e0, e1, e2 = _to_rgb(box[ly, lx, 0], box[ly, lx, 1], box[ly, lx, 2])
    else:
        e0 = (w00 * lr[y0, x0, 0] + w01 * lr[y0, x1, 0] + w10 * lr[y1, x0, 0] + w11 * lr[y1, x1, 0]) * inv
        e1 = (w00 * lr[y0, x0, 1] + w01 * lr[y0, x1, 1] + w10 * lr[y1, x0, 1] + w11 * lr[y1, x1, 1]) * inv
        e2 = (w00 * lr[y0, x0, 2] + w01 * lr[y0, x1, 2] + w10 * lr[y1, x0, 2] + w11 * lr[y1, x1, 2]) * inv
    # 2. motion of the nearest LR sample
    d = depth[ly, lx]
    sy = y + scale * motion[ly, lx, 1]
    sx = x + scale * motion[ly, lx, 0]
    n = 0.0
    h0 = h1 = h2 = 0.0
    if has_history and -0.5 < sy < hr_h - 0.5 and -0.5 < sx < hr_w - 0.5:
        sy = min(max(sy, 0.0), hr_h - 1.0)
        sx = min(max(sx, 0.0), hr_w - 1.0)
        iy, ix = int(sy), int(sx)
        ty, tx = sy - iy, sx - ix
        iy1, ix1 = min(iy + 1, hr_h - 1), min(ix + 1, hr_w - 1)
        # 4. disocclusion (depth, where the neighbourhood shows parallax)
        dropped = False
        if disocclusion > 0.0 and box[ly, lx, 6] > 0.5:
            dropped = d - _nearest_depth(history, iy, iy1, ix, ix1) > disocclusion
        if not dropped:  # 3. accumulated weight (bilinear) and Catmull-Rom colour
            n = _history_weight(history, iy, iy1, ix, ix1, tx, ty, cap)
        if n > 0.0 and not flat:
            ay = _catmull_rom_weights(ty)
            rows = (max(iy - 1, 0), iy, iy1, min(iy + 2, hr_h - 1))
            h0, h1, h2 = _mix(_catmull_rom_weights(tx), _history_column(history, max(ix - 1, 0), rows, ay),
                              _history_column(history, ix, rows, ay), _history_column(history, ix1, rows, ay),
                              _history_column(history, min(ix + 2, hr_w - 1), rows, ay))
            if rectify:  # 5. clamp into the YCoCg box of the 3x3 LR neighbourhood
                h0, h1, h2 = _clamp_to_ycocg_bounds(h0, h1, h2, box[ly, lx, 0], box[ly, lx, 1], box[ly, lx, 2],
                                                    box[ly, lx, 3], box[ly, lx, 4], box[ly, lx, 5])
    # 7. blend
    if flat:
        o0, o1, o2 = e0, e1, e2
    elif n > 0.0:
        share = 1.0 / (n + a)
        o0, o1, o2 = (n * h0 + a * e0) * share, (n * h1 + a * e1) * share, (n * h2 + a * e2) * share
    else:
        o0, o1, o2 = e0, e1, e2
    out[y, x, 0], out[y, x, 1], out[y, x, 2] = o0, o1, o2
    new_history[y, x, 0], new_history[y, x, 1], new_history[y, x, 2] = o0, o1, o2
    new_history[y, x, 3] = min(n + a, cap)
    new_history[y, x, 4] = d


class CudaTemporalUpsampler(TemporalUpsampler):
    """:class:`~volsr_core.temporal.taau.TemporalUpsampler` on the GPU: the same settings and steps, its history,
    inputs and output device arrays (host arrays are copied there). ``side_outputs`` is always off."""

    def __init__(self, scale: int, **settings):
        super().__init__(scale, **{**settings, "side_outputs": False})
        self._moving = MotionFlag()

    def __call__(self, lr_color, lr_motion, jitter: tuple[float, float], depth=None, rotation: float | None = None,
                 pixels_per_voxel: float | None = None, *, background=None, out=None):
        """As :meth:`TemporalUpsampler.__call__`; returns a new (h * scale, w * scale, 3) float32 device array, or
        ``out`` (a device array of that shape) written with it. ``background`` is not read: on the GPU the filter
        runs on the whole frame (:meth:`background_window` stays None)."""
        lr, motion = _device(lr_color), _device(lr_motion)
        if len(lr.shape) != 3 or lr.shape[2] != 3 or tuple(motion.shape) != tuple(lr.shape[:2]) + (2,):
            raise ValueError(f"expected colour (h, w, 3) and motion (h, w, 2), got {lr.shape} and {motion.shape}")
        jx, jy = checked_jitter(jitter)
        h, w = lr.shape[:2]
        if depth is None:
            depth_arr, disocclusion = cuda.to_device(np.ones((h, w), dtype=np.float32)), 0.0
        else:
            depth_arr, disocclusion = _device(depth), self.disocclusion
            if tuple(depth_arr.shape) != (h, w):
                raise ValueError(f"depth must be (h, w), got {depth_arr.shape}")
        s = self.scale
        shape = (h * s, w * s, 5)
        has = self.history is not None and tuple(self.history.shape) == shape
        history = self.history if has else cuda.device_array((1, 1, 5), dtype=np.float32)
        static, _, sigma, cap, tent = self._frame_settings(lambda: self._moving(motion, 0), has, rotation,
                                                           pixels_per_voxel)
        if self._box is None or tuple(self._box.shape[:2]) != (h, w):
            self._box = cuda.device_array((h, w, 8), dtype=np.float32)
        _taau_prepass[_blocks(w, h), THREADS](lr, motion, s, self.dis_motion, self._box)
        new_history = self._spare if self._spare is not None and tuple(self._spare.shape) == shape else \
            cuda.device_array(shape, dtype=np.float32)
        out = _output(out, shape[:2] + (3,))
        _taau_pixels[_blocks(w * s, h * s), THREADS](history, has, lr, motion, depth_arr, self._box, s, jx, jy,
                                                    1.0 / (2.0 * sigma * sigma), tent, cap, disocclusion, not static,
                                                    out, new_history)
        self._spare = self.history if has else None
        self.history = new_history
        return out


# -- the layered TAAU ---------------------------------------------------------------------------------------------
@cuda.jit
def _layered_prepass(slabs, box, info):
    """LR pixel (i, j), per slab: over its 3x3 neighbourhood (edges cut off) the RGBA min/max (only with ``box``), the
    motion the HR pixels nearest it take (its own where its slab shows something, else that of the most opaque
    neighbour, the first in row order among equals) and whether any of the nine shows something, into ``info``
    (K, h, w, _INFO) as ``layered._prepass`` writes it."""
    i, j = cuda.grid(2)
    n_slabs, h, w = slabs.shape[0], slabs.shape[1], slabs.shape[2]
    if j >= h or i >= w:
        return
    for k in range(n_slabs):
        lo0 = lo1 = lo2 = lo3 = float32(1e30)
        hi0 = hi1 = hi2 = hi3 = float32(-1e30)
        best = float32(_EMPTY)
        mx = my = float32(0.0)
        for yy in range(max(j - 1, 0), min(j + 2, h)):
            for xx in range(max(i - 1, 0), min(i + 2, w)):
                if box:
                    lo0, lo1 = min(lo0, slabs[k, yy, xx, SLAB_RGBA]), min(lo1, slabs[k, yy, xx, SLAB_RGBA + 1])
                    lo2, lo3 = min(lo2, slabs[k, yy, xx, SLAB_RGBA + 2]), min(lo3, slabs[k, yy, xx, SLAB_RGBA + 3])
                    hi0, hi1 = max(hi0, slabs[k, yy, xx, SLAB_RGBA]), max(hi1, slabs[k, yy, xx, SLAB_RGBA + 1])
                    hi2, hi3 = max(hi2, slabs[k, yy, xx, SLAB_RGBA + 2]), max(hi3, slabs[k, yy, xx, SLAB_RGBA + 3])
                if slabs[k, yy, xx, SLAB_RGBA + 3] > best:
                    best = slabs[k, yy, xx, SLAB_RGBA + 3]
                    mx, my = slabs[k, yy, xx, SLAB_MOTION], slabs[k, yy, xx, SLAB_MOTION + 1]
        if slabs[k, j, i, SLAB_RGBA + 3] > _EMPTY:
            mx, my = slabs[k, j, i, SLAB_MOTION], slabs[k, j, i, SLAB_MOTION + 1]
        info[k, j, i, 0], info[k, j, i, 1], info[k, j, i, 2], info[k, j, i, 3] = lo0, lo1, lo2, lo3
        info[k, j, i, 4], info[k, j, i, 5], info[k, j, i, 6], info[k, j, i, 7] = hi0, hi1, hi2, hi3
        info[k, j, i, 8], info[k, j, i, 9] = mx, my
        info[k, j, i, 10] = 1.0 if best > _EMPTY else 0.0


@cuda.jit
def _layered_pixels(history, has_history, slabs, info, scale, jx, jy, inv2s2, tent, cap, rectify, background, out,
                    new_history):
    """HR pixel (x, y): the layered TAAU's steps per slab, then the slabs composited front to back over
    ``background`` (``LayeredUpsampler``)."""
    x, y = cuda.grid(2)
    n_slabs, hr_h, hr_w = new_history.shape[0], new_history.shape[1], new_history.shape[2]
    if y >= hr_h or x >= hr_w:
        return
    lr_h, lr_w = slabs.shape[1], slabs.shape[2]
    ly, y0, y1, dy0, wy0, wy1 = _sample_window(y, scale, jy, lr_h, inv2s2)
    lx, x0, x1, fx, wx0, wx1 = _sample_window(x, scale, jx, lr_w, inv2s2)
    w00, w01, w10, w11, a, inv = _splat_weights(wy0, wy1, wx0, wx1, dy0, fx, tent)
    acc = cuda.local.array(4, float32)  # the composite so far: premultiplied RGB and alpha
    for c in range(4):
        acc[c] = 0.0
    for k in range(n_slabs):
        if info[k, ly, lx, 10] == 0.0:  # the slab shows nothing around here: an empty history
            for c in range(5):
                new_history[k, y, x, c] = 0.0
            continue
        sy = y + scale * info[k, ly, lx, 9]
        sx = x + scale * info[k, ly, lx, 8]
        n = 0.0
        b00 = b01 = b10 = b11 = 0.0
        iy = iy1 = ix = ix1 = 0
        if has_history and -0.5 < sy < hr_h - 0.5 and -0.5 < sx < hr_w - 0.5:
            sy = min(max(sy, 0.0), hr_h - 1.0)
            sx = min(max(sx, 0.0), hr_w - 1.0)
            iy = min(int(sy), hr_h - 2) if hr_h > 1 else 0
            ix = min(int(sx), hr_w - 2) if hr_w > 1 else 0
            iy1, ix1 = min(iy + 1, hr_h - 1), min(ix + 1, hr_w - 1)
            ty, tx = sy - iy, sx - ix
            b00, b01, b10, b11 = (1.0 - tx) * (1.0 - ty), tx * (1.0 - ty), (1.0 - tx) * ty, tx * ty
            n = min(_taps(history, k, iy, iy1, ix, ix1, 4, b00, b01, b10, b11), cap)
        share = 1.0 / (n + a)
        behind = 1.0 - acc[3]
        for c in range(4):
            o = _taps(slabs, k, y0, y1, x0, x1, c, w00, w01, w10, w11) * inv
            if n > 0.0:
                past = _taps(history, k, iy, iy1, ix, ix1, c, b00, b01, b10, b11)
                if rectify:
                    past = min(max(past, info[k, ly, lx, c]), info[k, ly, lx, 4 + c])
                o = (n * past + a * o) * share
            new_history[k, y, x, c] = o
            acc[c] += behind * o
        new_history[k, y, x, 4] = min(n + a, cap)
    behind = 1.0 - acc[3]
    for c in range(3):
        out[y, x, c] = acc[c] + behind * background[c]


class CudaLayeredUpsampler(LayeredUpsampler):
    """:class:`~volsr_core.temporal.layered.LayeredUpsampler` on the GPU: the same settings and steps, its histories,
    slabs and output device arrays (host arrays are copied there)."""

    def __init__(self, scale: int, **settings):
        super().__init__(scale, **settings)
        self._moving = MotionFlag()
        self._background: tuple[tuple[float, ...], object] | None = None  # (the RGB, it on the device)

    def _device_background(self, background) -> object:
        """``background`` as a device array, uploaded only when it changes (an upload costs about 0.2 ms)."""
        key = tuple(float(c) for c in background)
        if self._background is None or self._background[0] != key:
            self._background = key, cuda.to_device(np.asarray(key, dtype=np.float32))
        return self._background[1]

    def __call__(self, lr_slabs, jitter: tuple[float, float], background=(0.0, 0.0, 0.0),
                 rotation: float | None = None, pixels_per_voxel: float | None = None, *, out=None):
        """As :meth:`LayeredUpsampler.__call__`; returns a new (h * scale, w * scale, 3) float32 device array, or
        ``out`` (a device array of that shape) written with it."""
        slabs = _device(lr_slabs)
        if len(slabs.shape) != 4 or slabs.shape[3] != SLAB_CHANNELS or slabs.shape[0] < 1:
            raise ValueError(f"expected slabs (K, h, w, {SLAB_CHANNELS}), got {slabs.shape}")
        jx, jy = checked_jitter(jitter)
        n_slabs, h, w = slabs.shape[:3]
        s = self.scale
        shape = (n_slabs, h * s, w * s, 5)
        has = self.history is not None and tuple(self.history.shape) == shape
        history = self.history if has else cuda.device_array((1, 1, 1, 5), dtype=np.float32)
        static, still, sigma, cap, tent = self._frame_settings(
            lambda: self._moving(slabs.reshape(n_slabs * h, w, SLAB_CHANNELS), SLAB_MOTION), has, rotation,
            pixels_per_voxel)
        rectify = self._rectifies(static, still, pixels_per_voxel)
        if self._info is None or tuple(self._info.shape[:3]) != (n_slabs, h, w):
            self._info = cuda.device_array((n_slabs, h, w, _INFO), dtype=np.float32)
        _layered_prepass[_blocks(w, h), THREADS](slabs, rectify, self._info)
        new_history = self._spare if self._spare is not None and tuple(self._spare.shape) == shape else \
            cuda.device_array(shape, dtype=np.float32)
        out = _output(out, (h * s, w * s, 3))
        _layered_pixels[_blocks(w * s, h * s), THREADS](history, has, slabs, self._info, s, jx, jy,
                                                       1.0 / (2.0 * sigma * sigma), tent, cap, rectify,
                                                       self._device_background(background), out, new_history)
        self._spare = self.history if has else None
        self.history = new_history
        return out
