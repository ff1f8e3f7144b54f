"""A frame's depth slabs (``RayCaster.render(..., slabs=K)``, :attr:`~volsr_core.render.features.FeatureFrame.slabs`)
seen as a whole: how much of its opacity lies behind the front slab, and the K slabs composited into one.

Slabs are (K, H, W, SLAB_CHANNELS) float32, nearest first: per slab the premultiplied RGB and alpha of its samples
alone (``SLAB_RGBA``) and the motion vector of their opacity-weighted mean point (``SLAB_MOTION``, pixels).
"""
from __future__ import annotations

import numpy as np

from volsr_core.render.layout import SLAB_MOTION, SLAB_RGBA


def behind_front_share(slabs: np.ndarray) -> float:
    """The share of the frame's opacity (the sum over its pixels of the composite alpha) that the slabs behind the
    first add, seen through it: 0 where the front slab holds everything the view shows (an opaque look, or a frame
    in one slab), towards 1 where most of what shows lies behind it; 0 for an empty frame."""
    alpha = slabs[..., SLAB_RGBA + 3].astype(np.float64)
    whole = 1.0 - np.prod(1.0 - alpha, axis=0)
    total = float(whole.sum())
    return 0.0 if total <= 0.0 else float((whole - alpha[0]).sum()) / total


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
