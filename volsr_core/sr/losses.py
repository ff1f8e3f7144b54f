"""Losses: Charbonnier (the paper's), optionally plus an SSIM term and a temporal-stability term."""
from __future__ import annotations

import torch
import torch.nn.functional as F

#: Charbonnier epsilon. The paper uses 1e-8, which in float32 is plain L1 (|x| > 1e-4 for every
#: residual that matters). We use 1e-3: the same L1 behaviour for errors above ~1/255, but a
#: smooth, non-zero-curvature minimum, which AdamW handles better and AMP's fp16 can represent.
CHARBONNIER_EPS = 1e-3


def charbonnier(prediction: torch.Tensor, target: torch.Tensor, eps: float = CHARBONNIER_EPS) -> torch.Tensor:
    """mean(sqrt((prediction - target)^2 + eps^2))."""
    return torch.sqrt((prediction - target) ** 2 + eps * eps).mean()


def ssim(prediction: torch.Tensor, target: torch.Tensor, window: int = 7) -> torch.Tensor:
    """Mean SSIM over (B, C, H, W) images in [0, 1] with a uniform window (as scikit-image's default)."""
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    pool = lambda x: F.avg_pool2d(x, window, stride=1)  # noqa: E731
    mu_x, mu_y = pool(prediction), pool(target)
    var_x = pool(prediction * prediction) - mu_x ** 2
    var_y = pool(target * target) - mu_y ** 2
    cov = pool(prediction * target) - mu_x * mu_y
    n = window * window
    var_x, var_y, cov = var_x * n / (n - 1), var_y * n / (n - 1), cov * n / (n - 1)  # sample covariance
    s = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x ** 2 + mu_y ** 2 + c1) * (var_x + var_y + c2))
    return s.mean()


class ReconstructionLoss(torch.nn.Module):
    """Charbonnier plus ``ssim_weight * (1 - SSIM)`` (per frame; the temporal term is added by the trainer)."""

    def __init__(self, eps: float = CHARBONNIER_EPS, ssim_weight: float = 0.0):
        super().__init__()
        self.eps, self.ssim_weight = float(eps), float(ssim_weight)

    def forward(self, prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        loss = charbonnier(prediction, target, self.eps)
        if self.ssim_weight:
            loss = loss + self.ssim_weight * (1.0 - ssim(prediction.float(), target.float()))
        return loss


def temporal_charbonnier(output: torch.Tensor, previous_output: torch.Tensor, target: torch.Tensor,
                         previous_target: torch.Tensor, hr_motion: torch.Tensor,
                         eps: float = CHARBONNIER_EPS) -> torch.Tensor:
    """Charbonnier of the output's frame-to-frame change minus the ground truth's, after warping.

    The previous frames are backward-warped onto the current one with ``hr_motion`` (B, 2, H, W),
    HR pixels; pixels whose reprojection leaves the screen do not count. The training
    counterpart of :func:`volsr_core.apps.evaluate.temporal_error` (which is an L1 mean).
    """
    from volsr_core.sr.network import backward_warp

    ones = torch.ones_like(output[:, :1])
    warped = backward_warp(torch.cat([previous_output, previous_target, ones], 1), hr_motion)
    valid = (warped[:, -1:] > 0.999).to(output.dtype)
    change = (output - warped[:, :3]) - (target - warped[:, 3:6])
    per_pixel = torch.sqrt(change * change + eps * eps) * valid
    return per_pixel.sum() / (valid.sum() * 3).clamp(min=1.0)
