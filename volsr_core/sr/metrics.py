"""Image quality metrics from scikit-image (a maintained implementation, not hand-written)."""
from __future__ import annotations

import numpy as np
from skimage.metrics import peak_signal_noise_ratio, structural_similarity


def psnr_ssim(prediction: np.ndarray, target: np.ndarray, channel_axis: int = 0) -> tuple[float, float]:
    """PSNR (dB) and SSIM of an image in [0, 1] (prediction clipped) against its target."""
    p = np.clip(np.asarray(prediction, dtype=np.float64), 0.0, 1.0)
    t = np.asarray(target, dtype=np.float64)
    psnr = peak_signal_noise_ratio(t, p, data_range=1.0)
    ssim = structural_similarity(t, p, data_range=1.0, channel_axis=channel_axis)
    return float(psnr), float(ssim)
