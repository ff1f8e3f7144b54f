"""The ray-cast kernels for the CPU: the shared ray programs, one thread team over image rows."""
from __future__ import annotations

import numba
import numpy as np

from volsr_core.hashing import sources_sha256
from volsr_core.render import layout, stages
from volsr_core.render.stages import build_ray_program

_STAGE = numba.njit(inline="always", fastmath=True, boundscheck=False, cache=True)
march_ray = build_ray_program(_STAGE)
march_color = build_ray_program(_STAGE, features=False)


@numba.njit(inline="always", cache=True)
def _balanced_row(r, height):
    """Image row of the r-th row rendered: the top and bottom halves interleaved, so that each thread's share of
    rows (prange splits the range in contiguous chunks) samples the whole image: balanced work."""
    half = (height + 1) // 2
    return r // 2 if r % 2 == 0 else half + r // 2


def _row_kernel(sources: str, features: bool):
    """The kernel of one ray program (every feature, or the colour alone) over image rows; a closure over
    ``sources``, the digest of the modules whose stages and constants it compiles in
    (:func:`~volsr_core.hashing.sources_sha256`), so that numba's disk cache compiles it anew when those change, and
    over ``features``, a constant to numba: each kernel holds one program."""

    @numba.njit(parallel=True, fastmath=True, cache=True)
    def render_rows(vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs):
        sources  # noqa: B018 - it keys numba's disk cache on the stage modules (hashing.sources_sha256)
        for r in numba.prange(out.shape[0]):
            y = _balanced_row(r, out.shape[0])
            for x in range(out.shape[1]):
                if features:
                    march_ray(x, y, vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs)
                else:
                    march_color(x, y, vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs)

    return render_rows


_SOURCES = sources_sha256(stages, layout)
_render_rows, _render_color_rows = _row_kernel(_SOURCES, True), _row_kernel(_SOURCES, False)


def render_cpu(vol: np.ndarray, empty: np.ndarray, lut: np.ndarray, glut: np.ndarray, cam: np.ndarray,
               w2i: np.ndarray, grad_w: np.ndarray, params: np.ndarray, prev_vp: np.ndarray,
               out: np.ndarray, slabs: np.ndarray) -> None:
    """Fill ``out`` (H, W, OUT_CHANNELS) with every pixel's ray, on all CPU threads, and ``slabs`` (K, H, W,
    SLAB_CHANNELS) with its depth slabs when ``params[P_SLABS]`` is K > 0; an ``out`` of 3 channels gets the
    colour alone (the colour-only program)."""
    kernel = _render_color_rows if out.shape[2] == 3 else _render_rows
    kernel(vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs)
