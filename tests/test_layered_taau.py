"""Layered TAAU (``LayeredUpsampler``): one history per depth slab, each moved by its own vectors."""
from __future__ import annotations

import numpy as np
import pytest
from test_taau import pattern, psnr

from volsr_core.temporal import halton_jitter, jitter_phases
from volsr_core.temporal.color import fetch_bilinear, on_screen
from volsr_core.temporal.layered import _EMPTY, _INFO, LayeredUpsampler, _kernel, _prepass
from volsr_core.temporal.stages import SPLAT_FLOOR
from volsr_core.temporal.taau import TemporalUpsampler, _columns


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


def prepass_reference(slabs: np.ndarray) -> np.ndarray:
    """The prepass by its definition, pixel by pixel over each 3x3 neighbourhood (edges cut off): RGBA min and max,
    the motion of the pixel itself where its slab shows something, else of the most opaque of the nine (the first
    in row order among equals), and whether any of the nine shows something."""
    n_slabs, h, w = slabs.shape[:3]
    info = np.zeros((n_slabs, h, w, _INFO), np.float32)
    for k, j, i in np.ndindex(n_slabs, h, w):
        block = slabs[k, max(j - 1, 0):j + 2, max(i - 1, 0):i + 2].reshape(-1, 6)
        info[k, j, i, :4], info[k, j, i, 4:8] = block[:, :4].min(axis=0), block[:, :4].max(axis=0)
        first = int(np.argmax(block[:, 3]))  # numpy's argmax: the first of equal maxima, in row order
        shows = block[first, 3] > _EMPTY
        own = slabs[k, j, i, 3] > _EMPTY
        info[k, j, i, 8:10] = slabs[k, j, i, 4:6] if own else block[first, 4:6] if shows else 0.0
        info[k, j, i, 10] = float(shows)
    return info


def test_the_prepass_is_its_definition_ties_and_empty_slabs_included():
    rng = np.random.default_rng(3)
    slabs = rng.uniform(0.0, 1.0, (2, 9, 11, 6)).astype(np.float32)
    slabs[..., 3] = rng.choice([0.0, 5e-5, 0.25, 0.5, 1.0], size=(2, 9, 11))  # ties, and alphas at or below empty
    slabs[1, 2:6, 3:8, 3] = 0.0  # a patch of slab 1 shows nothing
    slabs[:, :, 9:, 3] = slabs[:, 7:, :, 3] = slabs[0, 0, :, 3] = 0.0  # margins that show nothing, and a row
    info, across = np.empty((2, 9, 11, _INFO), np.float32), np.empty((2, 9, 11, _INFO), np.float32)
    content = np.empty((2, 9, 2), np.int64)
    _prepass(slabs, True, across, info, content)
    reference = prepass_reference(slabs)
    # the prepass writes only where the 3x3 shows something: ``content`` spans it, first to last column of each row
    shown = reference[..., 10] > 0.0
    columns = np.arange(11)
    inside = (columns >= content[..., :1]) & (columns <= content[..., 1:])
    assert shown.any() and not shown.all() and not shown[~inside].any()
    for k, j in np.ndindex(2, 9):
        if shown[k, j].any():
            cols = np.flatnonzero(shown[k, j])
            assert (content[k, j, 0], content[k, j, 1]) == (cols[0], cols[-1])
        else:
            assert (content[k, j, 0], content[k, j, 1]) == (11, -1)
    np.testing.assert_array_equal(info[inside], reference[inside])
    _prepass(slabs, False, across, info, content)  # without the box (a frame that does not rectify): the rest alike
    np.testing.assert_array_equal(info[inside][:, 8:], reference[inside][:, 8:])


def window_reference(n: int, scale: int, jitter: float, lr_n: int, inv2s2: float):
    """Along one axis of ``n`` HR pixels: the nearest LR sample, the 2x2 window's two samples, the fraction past the
    first and their Gaussian weights (module docstring, step 1; positions as docs/conventions.md gives them)."""
    u = (np.arange(n) + 0.5) / scale - 0.5 - jitter
    f = np.floor(u)
    nearest = np.clip(np.floor(u + 0.5), 0, lr_n - 1).astype(int)
    first, second = np.clip(f, 0, lr_n - 1).astype(int), np.clip(f + 1, 0, lr_n - 1).astype(int)
    d = u - f
    return nearest, first, second, d, np.exp(-d * d * inv2s2), np.exp(-(d - 1.0) ** 2 * inv2s2)


def layered_reference(history, slabs, info, content, scale, jitter, sigma, tent, cap, rectify, background):
    """One step of the layered TAAU by the module docstring, pixel by pixel: per slab the splat (Gaussian, blended
    with the bilinear weights by ``tent``), the history fetched bilinearly where the nearest sample's vector points
    (``info``'s, from the prepass), clamped into its box with ``rectify``, blended; empty where the nearest sample's
    3x3 shows nothing; then the slabs composited front to back over ``background``. Returns (image, new history)."""
    n_slabs, h, w = slabs.shape[:3]
    big_h, big_w = h * scale, w * scale
    inv2s2 = 1.0 / (2.0 * sigma * sigma)
    ny, ry0, ry1, dy, gy0, gy1 = window_reference(big_h, scale, jitter[1], h, inv2s2)
    nx, rx0, rx1, dx, gx0, gx1 = window_reference(big_w, scale, jitter[0], w, inv2s2)
    image = np.empty((big_h, big_w, 3))
    new_history = np.zeros((n_slabs, big_h, big_w, 5))
    for y, x in np.ndindex(big_h, big_w):
        ly, lx = ny[y], nx[x]
        colour, behind = np.zeros(3), 1.0
        for k in range(n_slabs):
            if not content[k, ly, 0] <= lx <= content[k, ly, 1] or info[k, ly, lx, 10] == 0.0:
                continue
            weights = np.outer([gy0[y], gy1[y]], [gx0[x], gx1[x]])
            a = weights.sum()
            if a < SPLAT_FLOOR:  # the Gaussian all but vanished: the nearest of the four alone, at the least weight
                weights = np.zeros((2, 2))
                weights[int(dy[y] >= 0.5), int(dx[x] >= 0.5)] = a = SPLAT_FLOOR
            if tent > 0.0:
                weights = (1.0 - tent) * weights / a + tent * np.outer([1 - dy[y], dy[y]], [1 - dx[x], dx[x]])
            else:
                weights = weights / a
            taps = slabs[k][np.ix_([ry0[y], ry1[y]], [rx0[x], rx1[x]])][..., :4]
            estimate = np.einsum("ij,ijc->c", weights, taps)
            sy, sx = y + scale * info[k, ly, lx, 9], x + scale * info[k, ly, lx, 8]
            n, past = 0.0, np.zeros(5)
            if on_screen(sx, sy, big_w, big_h):
                fetch_bilinear(history[k], sx, sy, past)
                n = min(past[4], cap)
            if n > 0.0:
                rgba = np.clip(past[:4], info[k, ly, lx, :4], info[k, ly, lx, 4:8]) if rectify else past[:4]
                estimate = (n * rgba + a * estimate) / (n + a)
            new_history[k, y, x, :4], new_history[k, y, x, 4] = estimate, min(n + a, cap)
            colour, behind = colour + behind * estimate[:3], behind * (1.0 - estimate[3])
        image[y, x] = colour + behind * np.asarray(background)
    return image, new_history


@pytest.mark.parametrize("tent, rectify, sigma", [(0.0, False, 0.3), (0.0, True, 0.3), (0.4, True, 0.3),
                                                  (0.0, True, 0.04)])
def test_the_layered_step_is_its_definition(tent, rectify, sigma):
    """The row kernel (splat by columns blended per row, history columns carried along a run, its clamped edges) gives
    what the module docstring defines, pixel by pixel, with vectors that reach past every edge of the history; and it
    empties the pixels a reused buffer held where the slab now shows nothing. Sigma 0.04 LR px is a still view's narrow
    splat, whose Gaussian vanishes between the samples (``SPLAT_FLOOR``)."""
    rng = np.random.default_rng(7)
    n_slabs, lr, scale, jitter, cap = 2, 10, 4, (0.3, -0.2), 0.7
    slabs = np.zeros((n_slabs, lr, lr, 6), np.float32)
    alpha = rng.uniform(0.0, 1.0, (n_slabs, lr, lr)) * (rng.uniform(size=(n_slabs, lr, lr)) > 0.2)
    alpha[1, 3:7, 2:8] = 0.0  # a hole in the back slab: empty where its 3x3 shows nothing
    slabs[..., 3] = alpha
    slabs[..., :3] = alpha[..., None] * rng.uniform(0.0, 1.0, (n_slabs, lr, lr, 3))
    slabs[..., 4:6] = rng.uniform(-2.5, 2.5, (n_slabs, lr, lr, 2))  # LR px: up to 10 HR px, past the edges
    big = lr * scale
    history = rng.uniform(0.0, 1.0, (n_slabs, big, big, 5)).astype(np.float32)
    history[..., 4] *= 2.0 * (rng.uniform(size=(n_slabs, big, big)) > 0.3)  # weights, some zero
    info, across = np.empty((n_slabs, lr, lr, _INFO), np.float32), np.empty((n_slabs, lr, lr, _INFO), np.float32)
    content = np.empty((n_slabs, lr, 2), np.int64)
    _prepass(slabs, rectify, across, info, content)
    background = np.array([0.2, 0.4, 0.6], np.float32)
    cols, runs = _columns(big, lr, scale, jitter[0], 1.0 / (2.0 * sigma * sigma))
    out = np.empty((big, big, 3), np.float32)
    stale = rng.uniform(0.0, 1.0, (n_slabs, big, big, 5)).astype(np.float32)  # a reused buffer, shown everywhere
    new_history, shown = stale.copy(), np.ones((n_slabs, big, big), np.uint8)
    spans = np.tile(np.array([0, big], np.int64), (n_slabs, big, 1))
    _kernel(history, True, slabs, info, content, cols, runs, scale, jitter[1], 1.0 / (2.0 * sigma * sigma), tent,
            cap, rectify, background, out, new_history, shown, spans)
    image, reference = layered_reference(history, slabs, info, content, scale, jitter, sigma, tent, cap, rectify,
                                         background)
    empty = reference[..., 4] == 0.0
    assert empty[1].mean() > 0.05 and not empty.all()
    np.testing.assert_allclose(new_history, reference, rtol=1e-5, atol=2e-6)
    np.testing.assert_allclose(out, image, rtol=1e-5, atol=2e-6)
    np.testing.assert_array_equal(shown, ~empty)


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


def test_a_slab_history_is_zero_exactly_where_the_slab_shows_nothing_around_frame_after_frame():
    """The kernel writes an empty slab's pixels only where its buffer (one of two, alternating) last held something:
    a patch that jumps about and vanishes must leave no trace. Unjittered, HR pixel X's nearest LR sample is X //
    scale, so a slab's history must be non-zero exactly on the HR pixels of the LR samples within one of a shown
    one (the 3x3 the prepass looks at)."""
    rng = np.random.default_rng(5)
    scale, lr = 2, 12
    up = LayeredUpsampler(scale)
    for t in range(8):
        slabs = np.zeros((2, lr, lr, 6), dtype=np.float32)
        slabs[1, ..., :4] = (0.2, 0.3, 0.1, 0.4)  # the back slab shows everywhere
        shown = np.zeros((lr, lr), bool)
        if t not in (3, 6):  # frames 3 and 6: the front slab shows nothing at all
            j, i = rng.integers(0, lr - 3, 2)
            shown[j:j + 3, i:i + 2] = True
        slabs[0][shown] = (0.3, 0.2, 0.1, 0.6, 0.0, 0.0)
        slabs[..., 4:6] = rng.uniform(-1, 1, (2, lr, lr, 2))
        up(slabs, (0.0, 0.0), rotation=2.0)
        around = np.zeros_like(shown)
        for dj, di in np.ndindex(3, 3):
            around |= np.roll(np.pad(shown, 1), (dj - 1, di - 1), axis=(0, 1))[1:-1, 1:-1]
        hr_around = np.kron(around, np.ones((scale, scale), bool))
        assert np.all(up.history[0][~hr_around] == 0.0), f"frame {t}: a trace where the front slab shows nothing"
        assert np.all(up.history[0][hr_around][:, 4] > 0.0), f"frame {t}: no history where it shows"
        assert np.all(up.history[1][..., 4] > 0.0)


@pytest.mark.parametrize("scale", [2, 4])
def test_outside_its_background_window_the_layered_estimate_is_the_background(scale):
    """A patch shown in one slab, jittered and rotating: outside the window the layered TAAU reports, its estimate is
    the background exactly (it composites its slabs only within a 3x3 LR neighbourhood of what shows); the patch
    lies inside it; before any frame the window is unknown, and with nothing shown it is empty."""
    rng = np.random.default_rng(12)
    n, background = 16, (0.76, 0.76, 0.87)
    up = LayeredUpsampler(scale)
    assert up.background_window() is None
    for t in range(3):
        slabs = np.zeros((2, n, n, 6), dtype=np.float32)
        slabs[1, 6:9, 5:11, :4] = (0.3, 0.2, 0.1, 0.6)
        slabs[..., 4:6] = rng.uniform(-1, 1, (2, n, n, 2))
        out = up(slabs, halton_jitter(t, jitter_phases(scale)), background, rotation=2.0)
        top, bottom, left, right = up.background_window()
        assert (top, bottom, left, right) == (4 * scale, 11 * scale, 3 * scale, 13 * scale)  # the 3x3, 1 LR px more
        outside = np.ones(out.shape[:2], bool)
        outside[top:bottom, left:right] = False
        assert np.all(out[outside] == np.float32(background)) and np.any(out[~outside] != np.float32(background))
    up(np.zeros((2, n, n, 6), np.float32), (0.0, 0.0), background, rotation=2.0)
    assert up.background_window() == (0, 0, 0, 0)


@pytest.mark.parametrize("rotation, clamp_rotating, pixels_per_voxel, clamps", [
    (0.0, "never", None, True),  # a pan: clamped whatever the setting
    (2.0, "never", 0.5, False),
    (2.0, "fine", None, False),  # sampling unknown: not fine
    (2.0, "fine", 0.4, False),  # 1.6 output pixels a voxel, below the fine-sampling ramp (from 1.75)
    (2.0, "fine", 0.5, True),  # 2.0 output pixels a voxel: on it
    (2.0, "always", None, True),
])
def test_the_history_is_clamped_while_the_view_is_still_or_sampled_finely_and_blended_whole_otherwise(
        rotation: float, clamp_rotating: str, pixels_per_voxel: float | None, clamps: bool):
    """An opaque slab turns from one uniform colour to another between two frames that move (motion 0.25 LR px).
    While the view is still (a pan: the history may grow long), or rotates where ``clamp_rotating`` says (by default
    where the frame samples the volume finely), the 3x3 box of the new frame, a single colour, clamps the history to
    it: the new colour exactly. Otherwise the history, short under rotation, is not clamped: the output lies strictly
    between the two, the old colour's share that of the history's weight."""
    before, after = np.array([0.8, 0.2, 0.1], np.float32), np.array([0.1, 0.5, 0.9], np.float32)
    up = LayeredUpsampler(4, clamp_rotating=clamp_rotating)
    slabs = np.zeros((2, 8, 8, 6), dtype=np.float32)
    slabs[0, ..., :3], slabs[0, ..., 3] = before, 1.0
    up(slabs, (0.0, 0.0), rotation=rotation, pixels_per_voxel=pixels_per_voxel)
    slabs[0, ..., :3], slabs[0, ..., 4] = after, 0.25
    out = up(slabs, (0.25, -0.25), rotation=rotation, pixels_per_voxel=pixels_per_voxel)[8:24, 8:24]  # away from
    # the border the history is fetched from
    if clamps:
        np.testing.assert_allclose(out, np.broadcast_to(after, out.shape), atol=1e-6)
    else:
        old_share = (out - after) / (before - after)  # the same for every channel: one blend of two colours
        assert np.all(old_share > 0.05) and np.all(old_share < 0.95)
        np.testing.assert_allclose(old_share, old_share[..., :1].repeat(3, axis=-1), atol=1e-5)


def test_an_unknown_clamp_setting_is_refused():
    with pytest.raises(ValueError, match="clamp_rotating"):
        LayeredUpsampler(4, clamp_rotating=True)


def test_a_layered_estimate_written_into_out_is_the_one_returned_otherwise():
    fresh, into = LayeredUpsampler(4), LayeredUpsampler(4)
    buffer = np.full((64, 64, 3), np.nan, np.float32)
    for t in range(4):
        jitter = halton_jitter(t, jitter_phases(4))
        slabs = lr_slabs(16, 4, jitter, t, 1.5)
        expected = fresh(slabs, jitter, rotation=2.0)
        assert into(slabs, jitter, rotation=2.0, out=buffer) is buffer
        np.testing.assert_array_equal(buffer, expected)
    with pytest.raises(ValueError, match="out must be"):
        into(slabs, (0.0, 0.0), out=np.empty((64, 64, 3)))


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
