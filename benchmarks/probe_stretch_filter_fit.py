"""XS 2x's filter pair fitted through the stretch: what a filter made for the stretched 4x point would buy.

    python benchmarks/probe_stretch_filter_fit.py [--data out/dataset_motion] [--kernel 5]   # ~2 min, 2 cores
    python benchmarks/probe_stretch_filter_fit.py bench --volume V [--size 512]              # ~1 min a volume

The stretched 4x point (``Pipeline(..., scale=4, stretch=2)``) runs XS 2x, whose filter pair was fitted to the 2x
truth, and doubles its image by Keys' cubic (a = -0.75). The stretch is linear, so the pair that minimises the squared
error *after* it solves normal equations too: each pixel's k x k neighbourhood of TAAU's 2x estimate (clipped to
[0, 1], edges repeated), split by the pixel's orientation (``second_orientation``) into 2 k² columns, each column image
stretched by the same bicubic doubling (torch's, a = -0.75, edges repeated), against the 4x truth; no bias, a ridge as
``volsr_core/sr/least_squares.py``. Fitted on the dataset's train split at scale 4 (LR 64², TAAU 2x to 128², truth
256²), scored on its validation and test splits (the engine in MR-Angio; MR_Gd, held out): mean PSNR of the shipped
pair stretched, of the pair fitted through the stretch, and of TAAU's estimate stretched. ``bench`` scores the fitted
pair (``--weights``, written by the first form) on the bench's orbit (12 frames of 2°, frames 4-11, its 16-spp truth)
against the shipped one, each run by ``Pipeline(..., stretch=2)``.
"""
from __future__ import annotations

import argparse

import numpy as np
import torch
import torch.nn.functional as F
from bench_taau import REPO, orbit_parser, orbit_scene
from tqdm import tqdm

from volsr_core.runtime.models import model_file
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.sr.checkpoint import load_model
from volsr_core.sr.least_squares import RIDGE, design_matrix
from volsr_core.sr.loader import SequenceDataset
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.sr.network import second_orientation
from volsr_core.temporal.ground_truth import supersampled_truth

WEIGHTS = REPO / "out" / "probe_stretch_filter_fit.npy"
WARMUP = 4


def stretched(images: torch.Tensor) -> torch.Tensor:
    """(N, C, H, W) doubled by bicubic convolution, a = -0.75, edges repeated (the pipeline's stretch)."""
    return F.interpolate(images, scale_factor=2, mode="bicubic", align_corners=False)


def stretched_columns(base: torch.Tensor, kernel: int) -> torch.Tensor:
    """(3, 4P, 2 k²) float64: the design matrix of a filter pair on ``base`` (1, 3, H, W) (P = H W), stretched."""
    columns = design_matrix(base[0], kernel, bias=False)  # (3, P, k²)
    second = second_orientation(base)[0, 0].flatten().double()[None, :, None]
    pair = torch.cat([columns * (1.0 - second), columns * second], dim=2)
    height, width = base.shape[-2:]
    images = pair.permute(0, 2, 1).reshape(1, -1, height, width)
    return stretched(images).reshape(3, pair.shape[2], -1).permute(0, 2, 1)


def filtered(base: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """``base`` (1, 3, H, W) through a pair ``weights`` (2, 3, k, k) (no bias), each pixel taking its orientation's."""
    padded = F.pad(base, (weights.shape[-1] // 2,) * 4, mode="replicate")
    first, other = (F.conv2d(padded, weights[m][:, None], groups=3) for m in range(2))
    return first + second_orientation(base) * (other - first)


def fit(args: argparse.Namespace) -> None:
    model = load_model(model_file("XS", 2, "pt")).eval()
    data = {split: SequenceDataset(args.data, split, 4, 0, None, model.config.features, augment=False, seed=0,
                                   taau=model.config) for split in ("train", "val", "test")}
    unknowns = 2 * args.kernel * args.kernel
    normal = torch.zeros(3, unknowns, unknowns, dtype=torch.float64)
    moment = torch.zeros(3, unknowns, dtype=torch.float64)
    with torch.no_grad():
        for i in tqdm(range(len(data["train"])), desc="least squares", unit="frame"):
            item = data["train"][i]
            a = stretched_columns(torch.clamp(item["taau"][None, 0, :3].double(), 0.0, 1.0), args.kernel)
            normal += a.transpose(1, 2) @ a
            moment += (a.transpose(1, 2) @ item["hr"].reshape(3, -1, 1).double())[..., 0]
    ridge = RIDGE * normal.diagonal(dim1=-2, dim2=-1).mean(-1)[:, None, None] * torch.eye(unknowns, dtype=torch.float64)
    solution = torch.linalg.solve(normal + ridge, moment)
    fitted = solution.reshape(3, 2, args.kernel, args.kernel).transpose(0, 1).float()
    shipped = model.base_filter.weights()[0].float()
    WEIGHTS.parent.mkdir(parents=True, exist_ok=True)
    np.save(WEIGHTS, fitted.numpy())
    print(f"fitted pair written to {WEIGHTS}\n")
    print("| split | frames | shipped pair, stretched | fitted through the stretch | TAAU, stretched |")
    print("|---|---:|---:|---:|---:|")
    for split in ("val", "test"):
        scores = []
        with torch.no_grad():
            for i in range(len(data[split])):
                item = data[split][i]
                base = torch.clamp(item["taau"][None, 0, :3].float(), 0.0, 1.0)
                outs = (filtered(base, shipped), filtered(base, fitted), base)
                scores.append([psnr_ssim(torch.clamp(stretched(torch.clamp(o, 0.0, 1.0)), 0.0, 1.0)[0].numpy(),
                                         item["hr"].numpy())[0] for o in outs])
        print(f"| {split} | {len(scores)} | " + " | ".join(f"{v:.3f}" for v in np.mean(scores, 0)) + " |")


def bench(args: argparse.Namespace) -> None:
    scene, caster, cameras = orbit_scene(args)
    size = args.size
    truth = [supersampled_truth(caster, camera, t, size, size, 16) for t, camera in enumerate(cameras)]
    pipelines = [Pipeline(scene.volume, scene.transfer_function, scale=4, variant="XS", size=(size, size),
                          threads=2, stretch=2) for _ in range(2)]
    pipelines[1].upscaler.base_filter = (np.load(args.weights).astype(np.float32), np.zeros((2, 3), np.float32))
    scores: list[list[float]] = [[], []]
    for t, camera in enumerate(cameras):
        for pipeline, score in zip(pipelines, scores):
            image = pipeline.render(camera)
            if t >= WARMUP:
                score.append(psnr_ssim(image.transpose(2, 0, 1), truth[t].transpose(2, 0, 1))[0])
    shipped, fitted = (float(np.mean(s)) for s in scores)
    print(f"{scene.label}, {size}²: shipped {shipped:.3f} dB, fitted through the stretch {fitted:.3f} "
          f"({fitted - shipped:+.3f})")


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.add_argument("mode", nargs="?", choices=("fit", "bench"), default="fit")
    parser.add_argument("--data", default=str(REPO / "out" / "dataset_motion"))
    parser.add_argument("--kernel", type=int, default=5)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--weights", default=str(WEIGHTS))
    args = parser.parse_args()
    torch.set_num_threads(2)
    (bench if args.mode == "bench" else fit)(args)


if __name__ == "__main__":
    main()
