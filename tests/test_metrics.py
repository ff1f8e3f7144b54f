"""The image metrics: scikit-image's PSNR and SSIM, one pair at a time or many on threads."""
from __future__ import annotations

import numpy as np

from volsr_core.sr.metrics import psnr_ssim, psnr_ssim_many


def test_psnr_is_the_analytic_value_for_a_uniform_error():
    target = np.full((3, 16, 16), 0.5)
    psnr, ssim = psnr_ssim(target + 0.1, target)
    assert abs(psnr - 20.0) < 1e-9, "an error of 0.1 everywhere on a range of 1 is 20 dB"


def test_many_pairs_on_threads_score_as_one_call_after_another():
    rng = np.random.default_rng(3)
    target = rng.random((64, 48, 3)).astype(np.float32)
    pairs = [(np.clip(target + rng.normal(0, s, target.shape), 0, 1).astype(np.float32), target)
             for s in (0.01, 0.05, 0.2, 0.1)]
    expected = [psnr_ssim(p, t, channel_axis=-1) for p, t in pairs]
    assert psnr_ssim_many(pairs, channel_axis=-1, workers=3) == expected, "the same numbers, in the pairs' order"
