"""The ray-cast kernel for CUDA (numba-cuda): the same ray program as the CPU, one thread per pixel.

Importing this module needs ``numba.cuda`` (the ``numba-cuda`` package; ``pip install 'volsr[cuda]'``
pins a combination that imports). Set ``NUMBA_ENABLE_CUDASIM=1`` before importing numba to run it in
Numba's CUDA simulator (slow: tiny images only), which is how CI checks it on machines without a GPU.
"""
from __future__ import annotations

import numpy as np

if not hasattr(np, "row_stack"):  # NumPy >= 2.5 removed it; numba-cuda <= 0.30 still overloads it at import
    np.row_stack = np.vstack

from numba import cuda  # noqa: E402

from volsr_core.render.layout import P_SLABS  # noqa: E402
from volsr_core.render.stages import build_ray_program  # noqa: E402

march_ray = build_ray_program(cuda.jit(device=True, inline=True))
march_color = build_ray_program(cuda.jit(device=True, inline=True), features=False)

THREADS = (16, 8)


@cuda.jit
def _render_pixels(vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs):
    x, y = cuda.grid(2)
    if y < out.shape[0] and x < out.shape[1]:
        march_ray(x, y, vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs)


@cuda.jit
def _render_color_pixels(vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs):
    x, y = cuda.grid(2)
    if y < out.shape[0] and x < out.shape[1]:
        march_color(x, y, vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs)


class CudaVolume:
    """Device copies of a volume and of the arrays its renders read every frame (the empty-space mask, the
    transfer function's tables, the geometry), kept between frames: each array is uploaded again only when the
    caster hands over another object (a new transfer function builds new tables)."""

    def __init__(self, vol: np.ndarray):
        self.vol = cuda.to_device(vol)
        self._copies: dict[str, tuple[np.ndarray, object]] = {}

    def device_copy(self, name: str, host: np.ndarray):
        """The device copy of ``host``, kept under ``name``: made when ``host`` is not the object copied last."""
        kept = self._copies.get(name)
        if kept is None or kept[0] is not host:
            kept = self._copies[name] = (host, cuda.to_device(host))
        return kept[1]

    def set_empty(self, empty: np.ndarray) -> None:
        self.device_copy("empty", empty)

    @property
    def empty(self):
        """The device copy of the empty-space mask last set."""
        return self._copies["empty"][1]


def render_cuda(volume: CudaVolume, lut: np.ndarray, glut: np.ndarray, cam: np.ndarray, w2i: np.ndarray,
                grad_w: np.ndarray, params: np.ndarray, prev_vp: np.ndarray, out, slabs) -> None:
    """Fill ``out`` (H, W, OUT_CHANNELS) and, when ``params[P_SLABS]`` > 0, ``slabs`` on the GPU; an ``out`` of 3
    channels gets the colour alone (the colour-only program). Host arrays are filled by copies back (only what
    ``out`` holds travels); device arrays (``numba.cuda.device_array``) are filled where they are, nothing copied."""
    height, width = out.shape[:2]
    on_device = hasattr(out, "copy_to_host")
    d_out = out if on_device else cuda.device_array(out.shape, dtype=out.dtype)
    d_slabs = slabs if on_device else cuda.device_array(slabs.shape, dtype=slabs.dtype)
    blocks = ((width + THREADS[0] - 1) // THREADS[0], (height + THREADS[1] - 1) // THREADS[1])
    kernel = _render_color_pixels if out.shape[2] == 3 else _render_pixels
    tables = [volume.device_copy(name, array) for name, array in (("lut", lut), ("glut", glut))]
    geometry = [volume.device_copy(name, array) for name, array in (("w2i", w2i), ("grad_w", grad_w))]
    kernel[blocks, THREADS](volume.vol, volume.empty, *tables, cuda.to_device(cam), *geometry, cuda.to_device(params),
                            cuda.to_device(prev_vp), d_out, d_slabs)
    if on_device:
        cuda.synchronize()  # the frame is ready when this returns, as after a copy: callers time the render
    else:
        d_out.copy_to_host(out)
        if params[P_SLABS] > 0:
            d_slabs.copy_to_host(slabs)
