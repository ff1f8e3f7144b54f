"""The super-resolution network, structured as the seed paper describes it (Devkota & Pattanaik).

Per frame (current t and N previous frames t-1..t-N, all at low resolution):

1. **feature extraction**: a residual block (3x3 conv 32 + ReLU, 3x3 conv to 8; a 1x1 conv to 8
   on the skip path; add; ReLU), its 8 channels concatenated with the frame's inputs;
2. **zero-upsampling** to the target resolution: each low-resolution sample is placed on the
   high-resolution pixel where it was taken (its frame's jitter), zeros elsewhere;
3. **backward warping** of every previous frame's upsampled features to the current frame with
   the motion vectors (bilinearly upsampled, times the scale), chained for t-2, t-3;
4. **reweighting**: 3 conv layers on the RGB-D of all frames, one output channel per previous
   frame, tanh scaled to [0, 10]; each channel multiplies all channels of one previous frame;
5. **reconstruction**: a U-Net (after Hofmann et al.: conv + LeakyReLU(0.1) + max-pool
   encoders, nearest-upsampling decoders with concatenated skips) producing RGB.

Beyond the paper, a network may take a ``history`` image (HR RGB) weighted by one more
reweighting channel, which carries information from many more frames than N:

- ``recurrent``: its own previous output, backward-warped to the current frame like a previous
  frame (a learned counterpart of TAA's history);
- ``taau_base``: the TAAU estimate of the current frame (:class:`~volsr_core.temporal.taau.
  TemporalUpsampler`, already reprojected and clamped), which is also the base the output adds
  its residual to instead of the bilinearly upscaled colour: the network starts from TAAU and
  learns what TAAU gets wrong (blur, ghosting, disocclusions); with ``taau_aux`` the history also
  holds what TAAU's blend threw away (:attr:`TemporalUpsampler.last_aux`: the reprojected history
  colour and its share of the blend), so the network sees the current frame's samples (its LR
  inputs), the history and TAAU's confidence in it apart, not only their blend.

Steps 4-5 run on the high-resolution stack *folded* by ``fold`` (pixel unshuffle): ``fold = 1``
is the paper's network at full resolution (variant L); ``fold = scale`` (variant S) runs every
convolution at the low resolution with the sub-pixel positions kept as channels, and unfolds
the output with a pixel shuffle. The output adds the bilinearly upscaled current colour
(residual learning), clamped to [0, 1] only by the loss's targets, not in the graph.

``base_kernel`` passes that base through a learned filter per colour channel first
(:class:`BaseFilter`). Variant XS is that filter alone (``widths`` empty: no steps 1-5): TAAU's
estimate, sharpened by a (2 * scale + 1)² kernel learned from the data, for a frame budget where
the U-Net does not fit.

Tensors: ``lr`` (B, N+1, C, h, w), index 0 the current frame; ``motion`` (B, N+1, 2, h, w) each
frame's vectors to its own previous frame in LR pixels (docs/conventions.md); ``jitter``
(B, N+1, 2) in LR pixels, +y down; ``history`` (B, ``history_channels``, H, W): the network's
output for the previous frame (recurrent) or TAAU's output for this frame, then with ``taau_aux``
its side outputs (taau_base); None stands in the
bilinearly upscaled current colour (a recurrent network's first frame after a cut). Output
(B, 3, H, W), H = h*scale, W = w*scale.
"""
from __future__ import annotations

from dataclasses import field

import torch
import torch.nn.functional as F
from torch import nn

from volsr_core.sr.network_config import (  # noqa: F401  (FEATURE_CHANNELS, SCALES, variant_config: re-exported)
    FEATURE_CHANNELS, ORIENTATION_LUMA, ORIENTATION_SMOOTHING, SCALES, NetworkConfig, variant_config)

class FeatureBlock(nn.Module):
    """The paper's per-frame residual block; returns the inputs with 8 learned channels appended."""

    def __init__(self, in_channels: int, hidden: int = 32, out: int = 8):
        super().__init__()
        self.conv1 = nn.Conv2d(in_channels, hidden, 3, padding=1)
        self.conv2 = nn.Conv2d(hidden, out, 3, padding=1)
        self.skip = nn.Conv2d(in_channels, out, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.conv2(F.relu(self.conv1(x)))
        return torch.cat([x, F.relu(y + self.skip(x))], dim=1)


def zero_upsample(x: torch.Tensor, jitter: torch.Tensor, scale: int) -> torch.Tensor:
    """(B, C, h, w) -> (B, C, h*s, w*s): each sample on the HR pixel where its ray went, zeros elsewhere.

    LR pixel (i, j) rendered with jitter (jx, jy) sampled LR position (i + 0.5 + jx, j + 0.5 + jy),
    i.e. HR pixel (s*i + ox, s*j + oy) with o = floor(s * (0.5 + jitter)), clamped to [0, s-1].
    """
    return F.pixel_shuffle(zero_upsample_folded(x, jitter, scale), scale)


def upsample_motion(motion: torch.Tensor, scale: int) -> torch.Tensor:
    """LR motion vectors (B, 2, h, w) in LR pixels -> HR vectors (B, 2, h*s, w*s) in HR pixels."""
    return F.interpolate(motion, scale_factor=scale, mode="bilinear", align_corners=False) * scale


def backward_warp(x: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
    """``out[y, x] = x[y + dy, x + dx]`` (bilinear between pixel centres, zeros off screen)."""
    b, _, h, w = x.shape
    ys = torch.arange(h, device=x.device, dtype=x.dtype).view(1, h, 1)
    xs = torch.arange(w, device=x.device, dtype=x.dtype).view(1, 1, w)
    gx = (2.0 * (xs + 0.5 + motion[:, 0]) / w) - 1.0
    gy = (2.0 * (ys + 0.5 + motion[:, 1]) / h) - 1.0
    grid = torch.stack([gx, gy], dim=-1)
    return F.grid_sample(x, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


class Reweighting(nn.Module):
    """3 convolutions on the RGB-D of all frames -> one weight in [0, 10] per previous frame (and history)."""

    def __init__(self, in_channels: int, weights: int, width: int = 32, first_kernel: int = 3):
        super().__init__()
        self.first = nn.Conv2d(in_channels, width, first_kernel, padding=first_kernel // 2)
        self.rest = nn.Sequential(nn.ReLU(), nn.Conv2d(width, width, 3, padding=1), nn.ReLU(),
                                  nn.Conv2d(width, weights, 3, padding=1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.after_first(self.first(x))

    def after_first(self, y: torch.Tensor) -> torch.Tensor:
        """The weights from the first layer's output."""
        return (torch.tanh(self.rest(y)) + 1.0) * 5.0


def second_orientation(x: torch.Tensor) -> torch.Tensor:
    """(B, 1, H, W), 1.0 where a base filter pair uses its second filter, else 0.0, for ``x`` (B, 3, H, W) in
    [0, 1]: where the local gradient's gx * gy, smoothed, is negative (edges running from the top left to the
    bottom right, y down), as :data:`~volsr_core.sr.network_config.ORIENTATION_SMOOTHING` defines it."""
    luma = sum(w * x[:, c:c + 1] for c, w in enumerate(ORIENTATION_LUMA))
    p = F.pad(luma, (1, 1, 1, 1), mode="replicate")
    product = 0.5 * (p[..., 1:-1, 2:] - p[..., 1:-1, :-2]) * 0.5 * (p[..., 2:, 1:-1] - p[..., :-2, 1:-1])
    taps = torch.tensor(ORIENTATION_SMOOTHING, dtype=x.dtype, device=x.device)
    r = len(ORIENTATION_SMOOTHING) // 2
    product = F.conv2d(F.pad(product, (r, r, 0, 0), mode="replicate"), taps.view(1, 1, 1, -1))
    product = F.conv2d(F.pad(product, (0, 0, r, r), mode="replicate"), taps.view(1, 1, -1, 1))
    return (product < 0).to(x.dtype)


class BaseFilter(nn.Module):
    """A learned ``kernel``² filter per colour channel (depthwise, edge pixels repeated past the border),
    starting as the identity: what the residual adds to, or (variant XS) the whole network. At scale s
    a blur of one LR pixel spans s HR pixels either way, hence XS's kernel of 2 * s + 1. With
    ``orientations`` 2 it is a pair, each pixel taking the one for its local orientation
    (:func:`second_orientation`): a linear filter cannot sharpen edges running both ways alike."""

    def __init__(self, kernel: int, orientations: int = 1):
        super().__init__()
        self.orientations = orientations
        self.conv = nn.Conv2d(3, 3 * orientations, kernel, groups=3)  # output channel c * orientations + m
        with torch.no_grad():
            self.conv.weight.zero_()
            self.conv.weight[:, 0, kernel // 2, kernel // 2] = 1.0
            self.conv.bias.zero_()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        r = self.conv.kernel_size[0] // 2
        y = self.conv(F.pad(x, (r, r, r, r), mode="replicate"))
        if self.orientations == 1:
            return y
        y = y.unflatten(1, (3, self.orientations))
        return y[:, :, 0] + second_orientation(x) * (y[:, :, 1] - y[:, :, 0])

    def weights(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(orientations, 3, k, k) weights and (orientations, 3) biases, filter m of channel c at [m, c]."""
        k, n = self.conv.kernel_size[0], self.orientations
        return (self.conv.weight.detach().reshape(3, n, k, k).transpose(0, 1),
                self.conv.bias.detach().reshape(3, n).transpose(0, 1))

    def set_weights(self, weights: torch.Tensor, bias: torch.Tensor) -> None:
        """The inverse of :meth:`weights`."""
        k, n = self.conv.kernel_size[0], self.orientations
        with torch.no_grad():
            self.conv.weight.copy_(weights.transpose(0, 1).reshape(3 * n, 1, k, k).to(self.conv.weight.dtype))
            self.conv.bias.copy_(bias.transpose(0, 1).reshape(3 * n).to(self.conv.bias.dtype))


class UNet(nn.Module):
    """Encoder-decoder with concatenated skips (after Hofmann et al.'s denoising autoencoder)."""

    def __init__(self, in_channels: int, out_channels: int, widths: tuple[int, ...], first_kernel: int = 3):
        super().__init__()
        act = nn.LeakyReLU(0.1)
        self.first = nn.Conv2d(in_channels, widths[0], first_kernel, padding=first_kernel // 2)
        self.inp = nn.Sequential(act, nn.Conv2d(widths[0], widths[0], 3, padding=1), act)
        self.down = nn.ModuleList(
            nn.Sequential(nn.Conv2d(widths[i], widths[i + 1], 3, padding=1), act) for i in range(len(widths) - 1))
        self.up = nn.ModuleList(
            nn.Sequential(nn.Conv2d(widths[i + 1] + widths[i], widths[i], 3, padding=1), act,
                          nn.Conv2d(widths[i], widths[i], 3, padding=1), act)
            for i in reversed(range(len(widths) - 1)))
        self.out = nn.Conv2d(widths[0], out_channels, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.after_first(self.first(x))

    def after_first(self, y: torch.Tensor) -> torch.Tensor:
        """The output from the first layer's output."""
        skips = [self.inp(y)]
        for down in self.down:
            skips.append(down(F.max_pool2d(skips[-1], 2)))
        y = skips.pop()
        for up in self.up:
            skip = skips.pop()
            y = F.interpolate(y, size=skip.shape[-2:], mode="nearest")
            y = up(torch.cat([y, skip], dim=1))
        return self.out(y)


class SuperResolutionNet(nn.Module):
    """The whole network; see the module docstring. ``forward(lr, motion, jitter[, history]) -> (B, 3, H, W)``."""

    def __init__(self, config: NetworkConfig = field(default_factory=NetworkConfig)):
        super().__init__()
        self.config = config
        c, n, d = config.in_channels, config.previous_frames, config.fold
        self.base_filter = BaseFilter(config.base_kernel, config.base_orientations) if config.base_kernel else None
        if not config.widths:  # XS: the learned base filter is the whole network
            return
        self.features = FeatureBlock(c, config.feature_width)
        frame_channels = c + 8
        self.rgbd = config.rgbd_channels
        history = config.history_channels if config.takes_history else 0
        # folded stacks hold d*d sub-pixels per channel: their first layer mixes them with a 1x1
        first = 1 if d > 1 else 3
        if config.weighted_inputs:
            self.reweight = Reweighting((len(self.rgbd) * (n + 1) + history) * d * d, config.weighted_inputs,
                                        config.reweight_width, first)
        self.reconstruct = UNet((frame_channels * (n + 1) + history) * d * d, 3 * d * d, config.widths, first)
        if config.taau_base:  # start as TAAU exactly: the residual is zero until training says otherwise
            nn.init.zeros_(self.reconstruct.out.weight)
            nn.init.zeros_(self.reconstruct.out.bias)

    def forward(self, lr: torch.Tensor, motion: torch.Tensor, jitter: torch.Tensor,
                history: torch.Tensor | None = None) -> torch.Tensor:
        cfg = self.config
        s, d, n = cfg.scale, cfg.fold, cfg.previous_frames
        b, frames, c, h, w = lr.shape
        if not cfg.widths:  # XS: the filtered base alone
            return self.base_filter(self.unfiltered_base(lr, history))
        base = self.unfiltered_base(lr)  # the bilinear upscale; a TAAU-based network's history replaces it below
        feats = self.features(lr.reshape(b * frames, c, h, w)).reshape(b, frames, -1, h, w)
        hr_motion = [upsample_motion(motion[:, k], s) for k in range(max(n, int(cfg.recurrent)))]
        flows = accumulated_flows(hr_motion[:n])
        warped_history = None
        if cfg.takes_history:
            warped_history = base if history is None else torch.clamp(history, 0.0, 1.0)
            if cfg.taau_base:
                base = warped_history[:, :3]  # already this frame's: not warped
            else:
                warped_history = backward_warp(warped_history, hr_motion[0])
        if self.base_filter is not None:
            base = self.base_filter(base)
        if d == 1:
            stack = hr_stack(feats, jitter, flows, s, d) + ([warped_history] if cfg.takes_history else [])
            rgbd = [x[:, self.rgbd] for x in stack[:n + 1]] + stack[n + 1:]
            weights = self.reweight(torch.cat(rgbd, 1)) if cfg.weighted_inputs else None
            out = self.reconstruct(torch.cat([stack[0]] + [stack[k] * weights[:, k - 1:k]
                                                            for k in range(1, len(stack))], 1))
        else:
            out = F.pixel_shuffle(self._folded(feats, jitter, flows, warped_history), d)
        return out + base

    def unfiltered_base(self, lr: torch.Tensor, history: torch.Tensor | None = None) -> torch.Tensor:
        """(B, 3, H, W): TAAU's estimate (``taau_base`` with a history), else the bilinearly upscaled current
        colour; what the residual (or, variant XS, the base filter alone) starts from."""
        if self.config.taau_base and history is not None:
            return torch.clamp(history[:, :3], 0.0, 1.0)
        return F.interpolate(lr[:, 0, :3], scale_factor=self.config.scale, mode="bilinear", align_corners=False)

    def _folded(self, feats: torch.Tensor, jitter: torch.Tensor, flows: list[torch.Tensor],
                history: torch.Tensor | None) -> torch.Tensor:
        """Reweighting and U-Net on the folded stack, exactly, without building the concatenation.

        Their first layers are 1x1 convolutions, so over the concatenated frames they are the sum
        of per-frame convolutions; a frame's reweighting factor, a per-pixel scalar, is applied
        after its convolution (on 32 channels, not C*d*d); with fold == scale the current
        frame's term applies the weights of its jitter slot to its LR features, since its folded
        zero-upsampling is zero in every other slot.
        """
        cfg = self.config
        s, d, n = cfg.scale, cfg.fold, cfg.previous_frames
        dd, rgbd = d * d, self.rgbd
        fast = d == s
        if fast:
            onehot = slot_onehot(jitter[:, 0], s)
            previous = folded_previous(feats, jitter, flows, s)
        else:
            current, *previous = hr_stack(feats, jitter, flows, s, d)
        block = feats.shape[2] * dd
        w_u = self.reconstruct.first.weight[:, :, 0, 0]
        y = self.reconstruct.first.bias.view(1, -1, 1, 1) + (
            slot_conv1x1(feats[:, 0], w_u[:, :block], onehot) if fast else conv1x1(current, w_u[:, :block]))
        if cfg.weighted_inputs:
            w_r = self.reweight.first.weight[:, :, 0, 0]
            r = len(rgbd) * dd
            y_r = self.reweight.first.bias.view(1, -1, 1, 1) + (
                slot_conv1x1(feats[:, 0, rgbd], w_r[:, :r], onehot) if fast
                else conv1x1(torch.cat([current[:, ch * dd:(ch + 1) * dd] for ch in rgbd], 1), w_r[:, :r]))
            for k, x in enumerate(previous, start=1):
                if fast:
                    y_r = y_r + pixelwise_conv1x1(x[..., rgbd], w_r[:, k * r:(k + 1) * r], feats.shape[3])
                else:
                    rgbd_k = torch.cat([x[:, ch * dd:(ch + 1) * dd] for ch in rgbd], 1)
                    y_r = y_r + conv1x1(rgbd_k, w_r[:, k * r:(k + 1) * r])
            if history is not None:  # the warped history (folded by the stride), after the frames' columns
                y_r = y_r + folded_conv1x1(history, w_r[:, (n + 1) * r:], d)
            weights = self.reweight.after_first(y_r)
            for k, x in enumerate(previous, start=1):
                w_k = w_u[:, k * block:(k + 1) * block]
                term = pixelwise_conv1x1(x, w_k, feats.shape[3]) if fast else conv1x1(x, w_k)
                y = y + weights[:, k - 1:k] * term
            if history is not None:
                y = y + weights[:, n:n + 1] * folded_conv1x1(history, w_u[:, (n + 1) * block:], d)
        return self.reconstruct.after_first(y)


def conv1x1(x: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """A bias-free 1x1 convolution with an (out, in) weight matrix."""
    return F.conv2d(x, weight[:, :, None, None])


def folded_conv1x1(x: torch.Tensor, weight: torch.Tensor, fold: int) -> torch.Tensor:
    """``conv1x1(pixel_unshuffle(x, fold), weight)`` as one convolution of ``x`` (B, C, H, W) with stride
    ``fold``: the same sums without the folded tensor, whose 6-D transpose took a fifth of the S 4x network's
    time in onnxruntime. ``weight`` is (out, C*fold*fold) in folded channel order (c*fold*fold + row*fold +
    column), which is the (out, C, fold, fold) kernel's own order."""
    return F.conv2d(x, weight.reshape(weight.shape[0], -1, fold, fold), stride=fold)


def pixelwise_conv1x1(x: torch.Tensor, weight: torch.Tensor, height: int) -> torch.Tensor:
    """``conv1x1`` of the folded layout, from channels-last (B, h*w, s*s, C) samples: (B, out, h, w).

    ``weight`` is (out, C*s*s) in folded channel order (c*s*s + slot); it is reordered to
    (slot, c) so that one matrix product over each pixel's s*s*C values does it.
    """
    b, n, s2, c = x.shape
    reordered = weight.reshape(weight.shape[0], c, s2).transpose(1, 2).reshape(weight.shape[0], s2 * c)
    y = torch.matmul(x.reshape(b, n, s2 * c), reordered.t())  # (B, h*w, out)
    return y.transpose(1, 2).reshape(b, weight.shape[0], height, n // height)


def slot_conv1x1(x: torch.Tensor, weight: torch.Tensor, onehot: torch.Tensor) -> torch.Tensor:
    """``conv1x1(zero_upsample_folded(x, ...), weight)`` from the LR ``x`` (B, C, h, w) and its slot.

    ``weight`` is (out, C*s*s) in folded channel order (c*s*s + slot); ``onehot`` (B, s*s) the slot.
    """
    selected = torch.einsum("ocs,bs->boc", weight.reshape(weight.shape[0], x.shape[1], -1), onehot)
    return torch.einsum("boc,bchw->bohw", selected, x)


def accumulated_flows(hr_motion: list[torch.Tensor]) -> list[torch.Tensor]:
    """Flows from the current frame to frames t-1, t-2, ...: the vectors chained through each frame.

    ``hr_motion[j]`` holds frame t-j's vectors to frame t-j-1 (HR pixels). The flow to t-k is the
    flow to t-k+1 plus frame t-k+1's vectors read where that flow lands, so each previous frame
    is resampled once, not once per step.
    """
    flows: list[torch.Tensor] = []
    for m in hr_motion:
        flows.append(m if not flows else flows[-1] + backward_warp(m, flows[-1]))
    return flows


def hr_stack(feats: torch.Tensor, jitter: torch.Tensor, flows: list[torch.Tensor], scale: int,
             fold: int) -> list[torch.Tensor]:
    """Per frame: zero-upsample to HR, backward-warp previous frames with their flow, fold by ``fold``."""
    out = []
    for k in range(feats.shape[1]):
        x = zero_upsample(feats[:, k], jitter[:, k], scale)
        if k:
            x = backward_warp(x, flows[k - 1])
        out.append(F.pixel_unshuffle(x, fold) if fold > 1 else x)
    return out


def folded_previous(feats: torch.Tensor, jitter: torch.Tensor, flows: list[torch.Tensor],
                    scale: int) -> list[torch.Tensor]:
    """The previous frames of :func:`hr_stack` with ``fold == scale``, without HR tensors, channels last.

    Each is (B, h*w, s*s, C): LR pixel, sub-pixel slot (dy*s + dx), channel. Bilinearly sampling
    a zero-upsampled image at q meets at most one sample per axis (samples lie ``scale`` >= 2
    pixels apart), so the warped value is that LR sample (the nearest lattice point) times the
    tent weight of its distance to q; the samples' channel vectors are gathered as rows of a
    channels-last table.
    """
    b, _, c, h, w = feats.shape
    s2 = scale * scale
    out = []

    def by_pixel(hr: torch.Tensor) -> torch.Tensor:
        """(B, H, W) -> (B, h*w, s*s): each LR pixel's s*s HR pixels, row-major."""
        return hr.reshape(b, h, scale, w, scale).permute(0, 1, 3, 2, 4).reshape(b, h * w, s2)

    ys = torch.arange(h * scale, device=feats.device, dtype=feats.dtype).view(1, -1, 1)
    xs = torch.arange(w * scale, device=feats.device, dtype=feats.dtype).view(1, 1, -1)
    first_row = (torch.arange(b, device=feats.device) * (h * w)).view(b, 1, 1)
    for k in range(1, feats.shape[1]):
        flow = flows[k - 1]
        qx, qy = by_pixel(xs + 0.5 + flow[:, 0]), by_pixel(ys + 0.5 + flow[:, 1])  # HR positions in frame t-k
        offset = torch.clamp(torch.floor(scale * (0.5 + jitter[:, k])), 0, scale - 1)
        ox, oy = offset[:, 0].view(b, 1, 1), offset[:, 1].view(b, 1, 1)
        ix = torch.round((qx - ox - 0.5) / scale)
        iy = torch.round((qy - oy - 0.5) / scale)
        inside = ((ix >= 0) & (ix <= w - 1) & (iy >= 0) & (iy <= h - 1)).to(feats.dtype)
        weight = inside * (F.relu(1.0 - torch.abs(qx - (scale * ix + ox + 0.5)))
                           * F.relu(1.0 - torch.abs(qy - (scale * iy + oy + 0.5))))
        rows = (first_row + torch.clamp(iy, 0, h - 1).long() * w + torch.clamp(ix, 0, w - 1).long()).reshape(-1)
        table = feats[:, k].permute(0, 2, 3, 1).reshape(b * h * w, c)
        picked = torch.index_select(table, 0, rows).reshape(b, h * w, s2, c)
        out.append(picked * weight.unsqueeze(-1))
    return out


def slot_onehot(jitter: torch.Tensor, scale: int) -> torch.Tensor:
    """(B, s*s) one-hot of the sub-pixel slot oy*s + ox that jitter (B, 2) puts each sample in."""
    offset = torch.clamp(torch.floor(scale * (0.5 + jitter)), 0, scale - 1)
    slot = offset[:, 1] * scale + offset[:, 0]
    slots = torch.arange(scale * scale, device=jitter.device, dtype=jitter.dtype)
    return (slots[None, :] == slot[:, None]).to(jitter.dtype)


def zero_upsample_folded(x: torch.Tensor, jitter: torch.Tensor, scale: int) -> torch.Tensor:
    """``pixel_unshuffle(zero_upsample(x, jitter, scale), scale)`` without the HR tensor: (B, C*s*s, h, w)."""
    b, c, h, w = x.shape
    onehot = slot_onehot(jitter, scale)
    return (x.unsqueeze(2) * onehot[:, None, :, None, None]).reshape(b, c * scale * scale, h, w)


def run_unrolled(model: nn.Module, lr: torch.Tensor, motion: torch.Tensor, jitter: torch.Tensor,
                 steps: int, previous_frames: int, history_mode: str,
                 taau: torch.Tensor | None = None) -> list[torch.Tensor]:
    """Run a network over ``steps`` consecutive frames, oldest first, with the history
    :func:`~volsr_core.sr.history.pick_history` picks for each step.

    ``lr``/``motion``/``jitter`` hold N + steps frames (index k = frame t-k, as for one call); the
    step for frame t-i sees frames t-i .. t-i-N. ``taau`` (B, steps, 3, H, W), index i = frame t-i:
    TAAU's estimate of each step's frame (for ``history_mode`` "taau"). A recurrent network's first
    step has no history (a cut) and each output is the next step's history. Returns the outputs for
    t-steps+1 .. t. ``model`` may be a DistributedDataParallel wrapper, hence the configuration
    passed apart.
    """
    from volsr_core.sr.history import pick_history

    outputs: list[torch.Tensor] = []
    for i in reversed(range(steps)):
        window = slice(i, i + previous_frames + 1)
        args = (lr[:, window], motion[:, window], jitter[:, window])
        history = pick_history(history_mode, outputs[-1] if outputs else None,
                               None if taau is None else taau[:, i])
        outputs.append(model(*args, history) if history_mode != "none" else model(*args))
    return outputs
