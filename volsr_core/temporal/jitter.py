"""Sub-pixel jitter offsets: the Halton (2, 3) sequence, as TAA and FSR2 use it."""
from __future__ import annotations

import math

import numpy as np


def halton(index: int, base: int) -> float:
    """The ``index``-th (1-based) element of the van der Corput sequence in ``base``, in [0, 1)."""
    if index < 1:
        raise ValueError("Halton index starts at 1")
    f, result = 1.0, 0.0
    while index > 0:
        f /= base
        result += f * (index % base)
        index //= base
    return result


def jitter_phases(scale: int) -> int:
    """Length of the Halton jitter cycle for an upscaling ``scale``: ceil(8 * scale**2), as FSR2 uses."""
    return int(math.ceil(8 * scale * scale))


def halton_jitter(frame: int, phases: int = 16) -> tuple[float, float]:
    """Jitter (jx, jy) in pixels, in [-0.5, 0.5), for ``frame`` (0-based), cycling every ``phases``.

    Uses Halton(2, 3) from index 1, so the offsets spread evenly over the pixel; +y is down.
    """
    i = frame % phases + 1
    return halton(i, 2) - 0.5, halton(i, 3) - 0.5


def jitter_sequence(n: int, phases: int | None = None) -> np.ndarray:
    """(n, 2) float32 array of :func:`halton_jitter` offsets for frames 0..n-1 (phases default n)."""
    phases = n if phases is None else phases
    return np.array([halton_jitter(f, phases) for f in range(n)], dtype=np.float32)


def sample_offset(jitter: float, scale: int) -> int:
    """Index (0..scale-1) of the HR pixel, inside its LR pixel's block of ``scale`` HR pixels, that a
    sample jittered by ``jitter`` LR pixels lands in (the network's zero-upsampling slot)."""
    return min(max(int(math.floor((0.5 + jitter) * scale)), 0), scale - 1)
