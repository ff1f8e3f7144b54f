"""Temporal anti-aliasing: the compute pass after ray casting that accumulates jittered frames.

Per pixel and frame: fetch the history where the surface point was in the previous frame
(docs/conventions.md: a motion vector (dx, dy) in pixels, +y down, points from the current
pixel to that place, so ``history[y + dy, x + dx]`` is read), bring it in YCoCg into the box of
the current frame's 3x3 neighbourhood (which rejects stale colours after disocclusion), blend
``out = w * history + (1 - w) * current`` and keep ``out`` as the next history. Where the fetch
leaves the screen the pixel restarts from the current frame.
"""
from __future__ import annotations

import numba
import numpy as np

from volsr_core.hashing import sources_sha256
from volsr_core.temporal import color, stages
from volsr_core.temporal.color import (
    check_options, clip_history, fetch_bilinear, fetch_catmull_rom, image_to_ycocg, on_screen,
)


@numba.njit(fastmath=True, boundscheck=False)  # cached as part of the kernel below, not apart
def _taa_row(y, history, current, ycocg, motion, weight, variance, gamma, catmull_rom, towards_centre, out):
    h, w = current.shape[0], current.shape[1]
    colour = np.empty(3, dtype=np.float32)
    for x in range(w):
        sx, sy = x + motion[y, x, 0], y + motion[y, x, 1]
        if not on_screen(sx, sy, w, h):
            out[y, x] = current[y, x]
            continue
        if catmull_rom:
            fetch_catmull_rom(history, sx, sy, colour)
        else:
            fetch_bilinear(history, sx, sy, colour)
        clip_history(colour, ycocg, x, y, variance, gamma, towards_centre)
        for c in range(3):
            out[y, x, c] = weight * colour[c] + (1.0 - weight) * current[y, x, c]


def _taa_rows(sources: str):
    """The blend over rows; a closure over ``sources``, the digest of the modules whose stages it compiles in
    (:func:`~volsr_core.hashing.sources_sha256`), so that numba's disk cache compiles it anew when those change."""

    @numba.njit(parallel=True, cache=True)
    def kernel(history, current, ycocg, motion, weight, variance, gamma, catmull_rom, towards_centre, out):
        sources  # noqa: B018 - it keys numba's disk cache on the colour and stage modules (hashing.sources_sha256)
        for y in numba.prange(current.shape[0]):
            _taa_row(y, history, current, ycocg, motion, weight, variance, gamma, catmull_rom, towards_centre, out)

    return kernel


_taa_kernel = _taa_rows(sources_sha256(color, stages))


class TemporalAntiAliasing:
    """Temporal anti-aliasing over a stream of jittered frames (one call per frame).

    - ``history_weight`` w in [0, 1): the history's share of each output (0.9 averages about
      ten frames).
    - ``clamp``: the box the history must fall in, from the current frame's 3x3 neighbourhood in
      YCoCg: ``"minmax"`` (per-channel min/max) or ``"variance"`` (mean -/+ ``variance_gamma``
      standard deviations).
    - ``rectify``: how the history is brought into the box: ``"clamp"`` per channel (default:
      converges closest to the supersampled image on thin structures) or ``"clip"`` towards the
      box centre (keeps hue, see :func:`volsr_core.temporal.color.clip_to_box`).
    - ``reprojection``: ``"bilinear"`` or ``"catmull_rom"`` history fetch (sharper under motion).

    The history restarts from the current frame on the first call, after :meth:`reset`, when the
    image size changes and, per pixel, where the reprojection leaves the screen.
    """

    def __init__(self, history_weight: float = 0.9, clamp: str = "minmax", reprojection: str = "bilinear",
                 variance_gamma: float = 1.0, rectify: str = "clamp"):
        if not 0.0 <= history_weight < 1.0:
            raise ValueError(f"history_weight must lie in [0, 1), got {history_weight}")
        check_options(clamp, rectify, reprojection, variance_gamma)
        self.history_weight = float(history_weight)
        self.clamp = clamp
        self.rectify = rectify
        self.reprojection = reprojection
        self.variance_gamma = float(variance_gamma)
        self.history: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the history: the next frame is output as it is."""
        self.history = None

    def __call__(self, color: np.ndarray, motion: np.ndarray) -> np.ndarray:
        """Accumulate ``color`` (H, W, 3) with its ``motion`` (H, W, 2, pixels); returns a new (H, W, 3) float32."""
        current = np.ascontiguousarray(color, dtype=np.float32)
        if current.ndim != 3 or current.shape[2] != 3 or motion.shape != current.shape[:2] + (2,):
            raise ValueError(f"expected colour (H, W, 3) and motion (H, W, 2), got {color.shape} and {motion.shape}")
        if self.history is None or self.history.shape != current.shape:
            output = current.copy()
        else:
            output = np.empty_like(current)
            _taa_kernel(self.history, current, image_to_ycocg(current), np.ascontiguousarray(motion, dtype=np.float32),
                        self.history_weight, self.clamp == "variance", self.variance_gamma,
                        self.reprojection == "catmull_rom", self.rectify == "clip", output)
        self.history = output
        return output.copy()
