"""Single-frame resampling: the pixel-centre convention, constants and ramps, PyTorch's interpolate, the clamp."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.temporal.resample import resize_bicubic, resize_bilinear, upscale_bicubic, upscale_bilinear


@pytest.mark.parametrize("upscale", [upscale_bilinear, upscale_bicubic])
@pytest.mark.parametrize("scale", [2, 3, 4])
def test_upscaling_keeps_constants_and_linear_ramps(upscale, scale):
    """Pixel-centre convention: HR pixel X samples LR continuous coordinate (X + 0.5) / scale."""
    h, w = 7, 9
    constant = np.full((h, w, 3), 0.37, dtype=np.float32)
    np.testing.assert_allclose(upscale(constant, scale), constant[0, 0, 0], atol=1e-6)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    lr = (0.1 + 0.06 * xs - 0.04 * ys).astype(np.float32)
    hr = upscale(lr, scale)
    assert hr.shape == (h * scale, w * scale) and hr.dtype == np.float32
    hys, hxs = (np.mgrid[0:h * scale, 0:w * scale] + 0.5) / scale
    margin = 1.5 if upscale is upscale_bicubic else 0.5  # LR pixels whose taps reach past the edge
    inside = ((hxs >= margin) & (hxs <= w - margin)) & ((hys >= margin) & (hys <= h - margin))
    np.testing.assert_allclose(hr[inside], (0.1 + 0.06 * hxs - 0.04 * hys)[inside], atol=1e-5)


@pytest.mark.parametrize("scale", [2, 3, 4])
def test_upscaling_matches_torch_interpolate(scale):
    torch = pytest.importorskip("torch")
    lr = np.random.default_rng(7).random((11, 13, 3), dtype=np.float32)
    nchw = torch.from_numpy(lr).permute(2, 0, 1)[None]
    for mode, ours in (("bilinear", upscale_bilinear(lr, scale)), ("bicubic", upscale_bicubic(lr, scale, a=-0.75))):
        theirs = torch.nn.functional.interpolate(nchw, scale_factor=scale, mode=mode, align_corners=False)
        np.testing.assert_allclose(ours, theirs[0].permute(1, 2, 0).numpy(), atol=1e-5)


@pytest.mark.parametrize("sizes", [((11, 13), (29, 17)), ((6, 4), (6, 4)), ((16, 20), (5, 7)), ((1, 3), (4, 9)),
                                   ((5, 1), (10, 2)), ((3, 2), (7, 4))])
def test_resizing_to_any_size_matches_torch_interpolate_and_clamps_in_the_same_pass(sizes):
    """The separable kernels (along rows, then down columns) at ratios up, none, down and mixed, one or three channels:
    PyTorch's interpolate to the same size; ``clamp`` gives ``np.clip`` of the unclamped result, where bicubic's
    overshoot at the random image's steps leaves [0, 1]."""
    torch = pytest.importorskip("torch")
    (h, w), (height, width) = sizes
    for channels in (1, 3):
        image = np.random.default_rng(h * w).random((h, w, channels), dtype=np.float32)
        nchw = torch.from_numpy(image).permute(2, 0, 1)[None]
        for mode, ours in (("bilinear", resize_bilinear(image, width, height)),
                           ("bicubic", resize_bicubic(image, width, height, a=-0.75))):
            theirs = torch.nn.functional.interpolate(nchw, size=(height, width), mode=mode, align_corners=False)
            assert ours.shape == (height, width, channels) and ours.dtype == np.float32
            np.testing.assert_allclose(ours, theirs[0].permute(1, 2, 0).numpy(), atol=1e-5)
        unclamped = resize_bicubic(image, width, height, a=-0.75)
        clamped = resize_bicubic(image, width, height, a=-0.75, clamp=(0.0, 1.0))
        np.testing.assert_array_equal(clamped, np.clip(unclamped, 0.0, 1.0))
        if (height, width) == (29, 17):
            assert unclamped.min() < 0.0 or unclamped.max() > 1.0, "an upscale that overshoots: the clamp is tested"
    assert resize_bilinear(image[..., 0], width, height).shape == (height, width), "an (h, w) image stays 2D"


@pytest.mark.parametrize("cubic", [False, True])
def test_a_doubled_rgb_row_slides_its_window_to_the_gathered_taps_sums(cubic):
    """VolSR's 2x stretch and the baseline's 1/2 size: an RGB row doubled in width takes its taps from one sliding
    window (``_across_row_doubled``) instead of gathering each output's; the same sums as the gathers, edges too,
    and other ratios and channel counts keep the gathers."""
    from volsr_core.temporal import resample

    image = np.random.default_rng(3).random((9, 12, 3), dtype=np.float32)
    phase_w = resample._doubling_weights(12, 24, cubic, -0.75)
    assert phase_w.shape == (2, 4 if cubic else 2)
    assert resample._doubling_weights(12, 36, cubic, -0.75).shape[0] == 0
    out = {}
    for name, weights in (("window", phase_w), ("gathers", phase_w[:0])):
        out[name] = np.empty((20, 24, 3), np.float32)
        resample._resample_kernel(image, *resample._axis_taps(9, 20, cubic, -0.75),
                                  *resample._axis_taps(12, 24, cubic, -0.75), weights, np.float32(-10.0),
                                  np.float32(10.0), out[name])
    np.testing.assert_allclose(out["window"], out["gathers"], atol=2e-7)
    assert np.abs(out["window"] - out["window"].mean()).max() > 0.1
