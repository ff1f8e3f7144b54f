"""A frame's depth slabs (``RayCaster.render(..., slabs=K)``, :attr:`~volsr_core.render.features.FeatureFrame.slabs`)
seen as a whole: where two of them mix in one pixel, and the K slabs composited into one.

Slabs are (K, H, W, SLAB_CHANNELS) float32, nearest first: per slab the premultiplied RGB and alpha of its samples
alone (``SLAB_RGBA``) and the motion vector of their opacity-weighted mean point (``SLAB_MOTION``, pixels).
"""
from __future__ import annotations

import numpy as np

from volsr_core.render.layout import SLAB_MOTION, SLAB_RGBA

SHOWN = 1e-3  # a pixel whose composite alpha is above this shows something
MIXED_SEEN = 0.05  # a slab that adds at least this to a pixel's composite alpha is seen there


def mixed_share(slabs: np.ndarray, seen: float = MIXED_SEEN) -> float:
    """The share of the frame's shown pixels (composite alpha above :data:`SHOWN`) where two slabs or more each add at
    least ``seen`` to the composite's alpha (a slab's alpha times the transmittance of those in front of it): where
    one history per pixel would blend layers that move apart under rotation. 0 for a frame in one slab, one that shows
    nothing, or a look whose front hides what lies behind it."""
    alpha = slabs[..., SLAB_RGBA + 3].astype(np.float64)
    behind = np.cumprod(1.0 - alpha, axis=0)  # transmittance behind each slab
    added = alpha * np.concatenate([np.ones_like(alpha[:1]), behind[:-1]], axis=0)
    shown = behind[-1] < 1.0 - SHOWN
    count = int(shown.sum())
    return 0.0 if count == 0 else float(((added >= seen).sum(axis=0) >= 2)[shown].sum()) / count


def composited(slabs: np.ndarray) -> np.ndarray:
    """The K slabs as one, (1, H, W, SLAB_CHANNELS) float32: their RGBA composited front to back, and the motion
    vectors weighted by what each slab adds to the composite's alpha (the motion of the slabs' mean point, where the
    ray caster's one slab would reproject the mean point of all the samples: the same to within the projection's
    curvature); 0 where every slab is empty."""
    out = np.zeros((1,) + slabs.shape[1:], dtype=np.float32)
    behind = np.ones(slabs.shape[1:3], dtype=np.float32)  # transmittance in front of the slab
    weight = np.zeros_like(behind)
    for slab in slabs:
        seen = behind * slab[..., SLAB_RGBA + 3]
        out[0, ..., SLAB_RGBA:SLAB_RGBA + 4] += behind[..., None] * slab[..., SLAB_RGBA:SLAB_RGBA + 4]
        out[0, ..., SLAB_MOTION:SLAB_MOTION + 2] += seen[..., None] * slab[..., SLAB_MOTION:SLAB_MOTION + 2]
        weight += seen
        behind *= 1.0 - slab[..., SLAB_RGBA + 3]
    shown = weight > 0.0
    out[0, shown, SLAB_MOTION:SLAB_MOTION + 2] /= weight[shown, None]
    return out
