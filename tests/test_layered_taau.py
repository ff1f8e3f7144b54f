"""Layered TAAU (``LayeredUpsampler``): one history per depth slab, each moved by its own vectors."""
from __future__ import annotations

import numpy as np
import pytest
from test_taau import pattern, psnr

from volsr_core.temporal import halton_jitter, jitter_phases
from volsr_core.temporal.layered import LayeredUpsampler
from volsr_core.temporal.taau import TemporalUpsampler


def layers(x: np.ndarray, y: np.ndarray, t: int, speed: float) -> list[tuple[np.ndarray, float]]:
    """Two layers at HR coordinates (x, y) in frame t: in front a half-transparent pattern moving right by ``speed``
    HR px per frame, behind an opaque one moving left as fast; (colour, alpha) each, nearest first."""
    front = pattern(x - speed * t, y)
    back = pattern(0.7 * (x + speed * t) + 13.0, 1.3 * y)[..., ::-1]
    return [(front, 0.5), (back, 1.0)]


def composite(parts: list[tuple[np.ndarray, float]]) -> np.ndarray:
    colour, behind = 0.0, 1.0
    for rgb, alpha in parts:
        colour, behind = colour + behind * alpha * rgb, behind * (1.0 - alpha)
    return colour


def lr_slabs(lr: int, scale: int, jitter, t: int, speed: float) -> np.ndarray:
    """(2, lr, lr, 6) slabs sampled at the jittered LR positions: premultiplied RGBA and each layer's own vector
    (LR px, to where the point was a frame ago)."""
    ys, xs = np.mgrid[0:lr, 0:lr].astype(np.float64)
    x, y = (xs + 0.5 + jitter[0]) * scale, (ys + 0.5 + jitter[1]) * scale
    slabs = np.zeros((2, lr, lr, 6), dtype=np.float32)
    for k, (rgb, alpha) in enumerate(layers(x, y, t, speed)):
        slabs[k, ..., :3], slabs[k, ..., 3] = alpha * rgb, alpha
        slabs[k, ..., 4] = (-speed if k == 0 else speed) / scale
    return slabs


def test_layers_moving_apart_keep_their_history_where_one_vector_per_pixel_loses_it():
    """Parallax, the case the slabs are for: TAAU, given the composite and the front layer's vectors (what the
    renderer's opacity-threshold point gives here), smears the back layer; the layered history does not."""
    scale, lr, speed = 4, 24, 1.5
    layered, single = LayeredUpsampler(scale), TemporalUpsampler(scale)
    ys, xs = np.mgrid[0:lr * scale, 0:lr * scale].astype(np.float64)
    gains = []
    for t in range(12):
        jitter = halton_jitter(t, jitter_phases(scale))
        slabs = lr_slabs(lr, scale, jitter, t, speed)
        colour = slabs[0, ..., :3] + (1.0 - slabs[0, ..., 3:4]) * slabs[1, ..., :3]
        ours = layered(slabs, jitter, rotation=2.0)
        theirs = single(colour, np.ascontiguousarray(slabs[0, ..., 4:6]), jitter, rotation=2.0)
        if t >= 4:
            reference = composite(layers(xs + 0.5, ys + 0.5, t, speed))
            inner = (slice(8, -8), slice(8, -8))
            gains.append(psnr(ours[inner], reference[inner]) - psnr(theirs[inner], reference[inner]))
    print("layered - TAAU, dB per frame:", np.round(gains, 2))
    assert min(gains) > 1.0


def test_constant_slabs_stay_constant_over_the_background_under_any_motion_and_jitter():
    rng = np.random.default_rng(4)
    up = LayeredUpsampler(2)
    slabs = np.zeros((3, 9, 11, 6), dtype=np.float32)
    slabs[0, ..., :4] = (0.15, 0.1, 0.05, 0.5)  # half-transparent, premultiplied
    slabs[2, ..., :4] = (0.2, 0.3, 0.1, 0.4)  # slab 1 shows nothing
    expected = np.array([0.15, 0.1, 0.05]) + 0.5 * np.array([0.2, 0.3, 0.1]) + 0.5 * 0.6 * np.array([0.9, 0.8, 0.7])
    for k in range(6):
        slabs[..., 4:6] = rng.uniform(-2, 2, (3, 9, 11, 2))
        out = up(slabs, halton_jitter(k, 16), background=(0.9, 0.8, 0.7), rotation=2.0 * (k % 2))
        assert out.shape == (18, 22, 3)
        np.testing.assert_allclose(out, np.broadcast_to(expected, out.shape), atol=1e-5)
        assert np.all(up.history[1] == 0.0), "an empty slab keeps an empty history"


def test_a_change_in_slabs_or_size_starts_a_new_history():
    up = LayeredUpsampler(2)
    up(np.ones((2, 4, 4, 6), dtype=np.float32), (0.0, 0.0))
    assert up.history.shape == (2, 8, 8, 5)
    up(np.ones((3, 4, 5, 6), dtype=np.float32), (0.0, 0.0))
    assert up.history.shape == (3, 8, 10, 5)


def test_bad_arguments_are_rejected():
    up = LayeredUpsampler(2)
    with pytest.raises(ValueError, match="slabs"):
        up(np.zeros((4, 4, 6), dtype=np.float32), (0.0, 0.0))
    with pytest.raises(ValueError, match="slabs"):
        up(np.zeros((2, 4, 4, 3), dtype=np.float32), (0.0, 0.0))
    with pytest.raises(ValueError, match="jitter"):
        up(np.zeros((2, 4, 4, 6), dtype=np.float32), (0.5, 0.0))
