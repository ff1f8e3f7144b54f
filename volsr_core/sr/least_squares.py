"""Closed-form training of a network whose only weights are the linear filter on its base (variant XS).

XS's output is linear in its weights: per colour channel c, out_c(p) = b_c + sum_k w_ck base_c(p + o_k)
over the kernel's offsets o_k (edge pixels repeated past the border, as :class:`~volsr_core.sr.network.
BaseFilter` pads); a filter pair (``base_orientations`` 2) is that per orientation, each pixel's
orientation fixed by the base alone. The weights with the least squared error over the training frames,
the error PSNR scores, solve the normal equations: one (k² + 1)-unknown system per channel and
orientation, summed frame by frame over the pixels of that orientation, so no optimiser, learning rate
or steps (stochastic gradient descent on the same data, 1500 AdamW steps, got about half the gain).
Each frame's base is what the network is given at run time: TAAU's estimate of the whole frame
(:class:`~volsr_core.sr.history.HistoryFeed` over the video from its first frame) with ``taau_base``,
else the bilinear upscale.
"""
from __future__ import annotations

import csv
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from volsr_core.atomic import atomic_write
from volsr_core.sr.checkpoint import save_checkpoint
from volsr_core.sr.config import TrainingConfig
from volsr_core.sr.loader import SequenceDataset
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.sr.network import SuperResolutionNet, second_orientation

RIDGE = 1e-6  # Tikhonov term, relative to the mean diagonal of the normal matrix: keeps flat data solvable


def is_closed_form(model: SuperResolutionNet) -> bool:
    """Whether ``model``'s only weights are its base filter (no U-Net: variant XS)."""
    return not model.config.widths and model.base_filter is not None


def design_matrix(base: torch.Tensor, kernel: int, bias: bool = True) -> torch.Tensor:
    """(3, H, W) -> (3, H*W, kernel² + 1) float64: each pixel's kernel x kernel neighbourhood per channel
    (edge-padded, row-major as the convolution's weights), then a 1 for the bias (without ``bias``: k² columns)."""
    r = kernel // 2
    padded = F.pad(base[:, None].double(), (r, r, r, r), mode="replicate")  # (3, 1, H + 2r, W + 2r)
    columns = F.unfold(padded, kernel).transpose(1, 2)  # (3, H*W, k²)
    return torch.cat([columns, torch.ones_like(columns[..., :1])], dim=2) if bias else columns


def item_inputs(item: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor | None]:
    """A dataset item's current LR frame (1, 1, C, h, w) and TAAU history (1, C', H, W) or None."""
    return item["lr"][None, :1], item["taau"][None, 0] if "taau" in item else None


def fit_base_filter(model: SuperResolutionNet, dataset: SequenceDataset, progress: bool = True,
                    bias: bool = True) -> int:
    """Set ``model``'s base filter to the least-squares fit over every sample of ``dataset`` (whole
    frames: ``crop`` None); returns the pixels fitted per channel. Without ``bias`` the bias stays 0 (a black
    base stays black: a fitted bias of a few thousandths greys every background pixel, which SSIM punishes)."""
    from tqdm import tqdm

    base_filter = model.base_filter
    kernel, orientations = model.config.base_kernel, base_filter.orientations
    unknowns = kernel * kernel + int(bias)
    normal = torch.zeros(orientations, 3, unknowns, unknowns, dtype=torch.float64)
    moment = torch.zeros(orientations, 3, unknowns, dtype=torch.float64)
    pixels = 0
    with torch.no_grad():
        for i in tqdm(range(len(dataset)), desc="least squares", unit="frame", disable=not progress):
            item = dataset[i]
            base = model.unfiltered_base(*item_inputs(item))
            a = design_matrix(base[0], kernel, bias)
            target = item["hr"].reshape(3, -1, 1).double()
            second = second_orientation(base)[0, 0].flatten().bool() if orientations == 2 else None
            for m in range(orientations):
                rows = slice(None) if second is None else (second if m else ~second)
                am, tm = a[:, rows], target[:, rows]
                normal[m] += am.transpose(1, 2) @ am
                moment[m] += (am.transpose(1, 2) @ tm)[..., 0]
            pixels += a.shape[1]
        # each orientation's filter is drawn towards the one filter of all pixels by the ridge (an orientation
        # no training pixel had gets that filter)
        eye = torch.eye(unknowns, dtype=normal.dtype)
        ridge = RIDGE * normal.sum(0).diagonal(dim1=-2, dim2=-1).mean(dim=-1)[:, None, None] * eye  # (3, u, u)
        pooled = torch.linalg.solve(normal.sum(0) + ridge, moment.sum(0))
        solution = torch.linalg.solve(normal + ridge, moment + (ridge @ pooled[..., None])[..., 0])
        weights = solution[..., :kernel * kernel].reshape(orientations, 3, kernel, kernel)
        biases = solution[..., -1] if bias else torch.zeros(orientations, 3, dtype=weights.dtype)
        base_filter.set_weights(weights, biases)
    return pixels


@torch.no_grad()
def mean_psnr(model: SuperResolutionNet, dataset: SequenceDataset, limit: int) -> float:
    """Mean PSNR (scikit-image) of ``model`` on up to ``limit`` whole frames spread over ``dataset``."""
    n = min(len(dataset), limit)
    scores = []
    for i in np.linspace(0, len(dataset) - 1, n).round().astype(int) if n else []:
        item = dataset[int(i)]
        lr, history = item_inputs(item)
        out = model(lr, torch.zeros(1, 1, 2, *lr.shape[-2:]), item["jitter"][None, :1], history)
        scores.append(psnr_ssim(out[0].numpy(), item["hr"].numpy())[0])
    return float(np.mean(scores)) if scores else float("nan")


def train_base_filter(config: TrainingConfig, model: SuperResolutionNet, progress: bool = True) -> dict[str, Any]:
    """``volsr train`` for a closed-form network: fit on the train split, score the validation split, write
    ``OUT/best.pt`` and a one-row ``OUT/log.csv`` (the optimiser, steps and loss of the config are unused)."""
    from volsr_core.sr.training import LOG_FIELDS, run_folder_lock

    data, out = config.data, Path(config.out)
    started = time.perf_counter()
    datasets = {split: SequenceDataset(data.root, split, data.scale, 0, None, data.features, augment=False,
                                       seed=config.seed, taau=model.config if model.config.taau_base else None)
                for split in ("train", "val")}
    with run_folder_lock(out):
        pixels = fit_base_filter(model, datasets["train"], progress, config.train.fit_bias)
        psnr = mean_psnr(model, datasets["val"], config.train.max_val_samples)
        save_checkpoint(out / "best.pt", model, extra={"step": 1, "psnr": psnr, "fitted_pixels": pixels})
        row = {"step": 1, "epoch": 0, "loss": "", "lr": "", "val_psnr": f"{psnr:.4f}", "val_ssim": "",
               "seconds": f"{time.perf_counter() - started:.1f}"}
        with atomic_write(out / "log.csv", "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=LOG_FIELDS)
            writer.writeheader()
            writer.writerow(row)
    return {"step": 1, "best_psnr": psnr}
