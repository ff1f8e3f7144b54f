"""The ray-cast kernel for the CPU: the shared ray program, one thread team over image rows."""
from __future__ import annotations

import numba
import numpy as np

from volsr_core.render.stages import build_ray_program

march_ray = build_ray_program(numba.njit(inline="always", fastmath=True, boundscheck=False, cache=True))


@numba.njit(parallel=True, fastmath=True, cache=True)
def _render_rows(vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs):
    height, width = out.shape[0], out.shape[1]
    half = (height + 1) // 2
    for r in numba.prange(height):
        # interleave the top and bottom halves so that each thread's share of rows (prange
        # splits the range in contiguous chunks) samples the whole image: balanced work
        y = r // 2 if r % 2 == 0 else half + r // 2
        for x in range(width):
            march_ray(x, y, vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs)


def render_cpu(vol: np.ndarray, empty: np.ndarray, lut: np.ndarray, glut: np.ndarray, cam: np.ndarray,
               w2i: np.ndarray, grad_w: np.ndarray, params: np.ndarray, prev_vp: np.ndarray,
               out: np.ndarray, slabs: np.ndarray) -> None:
    """Fill ``out`` (H, W, OUT_CHANNELS) with every pixel's ray, on all CPU threads, and ``slabs`` (K, H, W,
    SLAB_CHANNELS) with its depth slabs when ``params[P_SLABS]`` is K > 0."""
    _render_rows(vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs)
