"""Single-frame resampling: the pixel-centre convention, constants and ramps, PyTorch's interpolate."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.temporal.resample import upscale_bicubic, upscale_bilinear


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
