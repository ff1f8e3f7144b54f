"""A 2x stretch fitted to XS 2x's half-size images instead of Keys' cubic: what it would buy, and what the training
videos would fit.

    python benchmarks/probe_stretch_kernel.py bench [--size 1024] [--kernel W0,W1,W2,W3 ...]   # ~12 min, 2 cores
    python benchmarks/probe_stretch_kernel.py videos training/configs/dataset_motion.yaml [--min-pixels-per-voxel 2]

The stretched 4x point (``Pipeline(..., scale=4, stretch=2)``) doubles XS 2x's image by Keys' cubic (a = -0.75). A
separable 4-tap doubling kernel generalises it: along each axis output 2k = sum_j w[j] input[k - 2 + j] and output
2k + 1 the mirror image (w reversed on inputs k - 1 .. k + 2), edges repeated; Keys' is w = (-0.0352, 0.2617, 0.8789,
-0.1055). Its least-squares w (the error PSNR scores) comes from alternating least squares: with w along x, the
4-unknown normal equations of the pass along y, pooled over the images and their transposes, normalised to sum 1,
until no weight moves by 1e-6.

- ``bench``: XS 2x's images at half ``--size`` and the 16-spp truth at ``--size`` on the bench's orbit (12 frames of
  2°, frames 4-11 scored, as ``volsr bench``) of the four bench volumes; mean PSNR of Keys' stretch and, per volume,
  of the separable kernel and of a free 4x4 filter per output phase (with a bias) fitted on the other volumes (MR_Gd:
  on the three CTs) or on the volume itself (an upper bound), and of each ``--kernel`` given.
- ``videos``: the kernel fitted on a dataset config's train-split videos (their cameras, rendered here: XS 2x at
  half the config's ``hr_size``, its ground truth at ``hr_size``), on the frames whose voxels span at least
  ``--min-pixels-per-voxel`` output pixels (where ``stretch="auto"`` stretches), and its PSNR there against Keys'.
"""
from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np
from bench_taau import DATA
from skimage.metrics import peak_signal_noise_ratio
from tqdm import tqdm

from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.runtime.pipeline import STRETCH_FROM, Pipeline
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.temporal import render_supersampled

KEYS = np.array([-0.03515625, 0.26171875, 0.87890625, -0.10546875])  # Keys' a = -0.75 at distances 1.75 .. 1.25
VOLUMES = ("CT_AVM.nii.gz:CT-AAA:0,446", "LIDC2.mha:CT-Bone:0,255", "bonsai.nii.gz:CT-Bone", "MR_Gd.nii.gz:MR-Default")
WARMUP = 4


def psnr(image: np.ndarray, truth: np.ndarray) -> float:
    """PSNR (dB) of ``image`` clipped to [0, 1] against ``truth`` (scikit-image's; ``psnr_ssim`` adds SSIM)."""
    return float(peak_signal_noise_ratio(truth.astype(np.float64), np.clip(image, 0.0, 1.0), data_range=1.0))


def phase_taps(n: int, phase: int) -> np.ndarray:
    """(n, 4) input indices for the outputs 2k + ``phase`` along an axis of ``n``, edges repeated; column j takes w[j]
    (for phase 1 the columns run k + 2 .. k - 1: the mirror image)."""
    offsets = np.arange(-2, 2) if phase == 0 else np.arange(2, -2, -1)
    return np.clip(np.arange(n)[:, None] + offsets, 0, n - 1)


def double_across(image: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(h, w, C) -> (h, 2w, C) float64, doubled along x by ``w``."""
    out = np.empty((image.shape[0], 2 * image.shape[1], image.shape[2]))
    for phase in (0, 1):
        out[:, phase::2] = np.einsum("hwjc,j->hwc", image[:, phase_taps(image.shape[1], phase)], w)
    return out


def double(image: np.ndarray, w: np.ndarray) -> np.ndarray:
    return double_across(double_across(image.astype(np.float64), w).transpose(1, 0, 2), w).transpose(1, 0, 2)


def fit_separable(pairs: list[tuple[np.ndarray, np.ndarray]], tolerance: float = 1e-6) -> np.ndarray:
    """The separable kernel of least squared error over ``pairs`` (half, truth), by alternating least squares."""
    w = KEYS.copy()
    for _ in range(60):
        a, b = np.zeros((4, 4)), np.zeros(4)
        for half, truth in pairs:
            for h, t in ((half, truth), (half.transpose(1, 0, 2), truth.transpose(1, 0, 2))):
                across = double_across(h.astype(np.float64), w)
                for phase in (0, 1):
                    x = np.moveaxis(across[phase_taps(h.shape[0], phase)], 1, -1).reshape(-1, 4)
                    y = t[phase::2].astype(np.float64).reshape(-1)
                    a, b = a + x.T @ x, b + x.T @ y
        previous, w = w, np.linalg.solve(a, b)
        w /= w.sum()
        if np.abs(w - previous).max() <= tolerance:
            return w
    return w


def phase_patches(half: np.ndarray, py: int, px: int) -> np.ndarray:
    """(h * w * C, 17): each output (2i + py, 2j + px)'s 4x4 inputs (the separable kernel's window) and a 1."""
    rows, cols = phase_taps(half.shape[0], py), phase_taps(half.shape[1], px)
    taps = half[rows[:, :, None, None], cols[None, None, :, :]]  # (h, 4, w, 4, C)
    x = np.moveaxis(taps, (1, 3), (3, 4)).reshape(-1, 16).astype(np.float64)
    return np.concatenate([x, np.ones((len(x), 1))], 1)


def fit_free(pairs: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    """A free 4x4 filter and a bias per output phase, shared by the channels: least squares."""
    filters = {}
    for py in (0, 1):
        for px in (0, 1):
            a, b = 0.0, 0.0
            for half, truth in pairs:
                x = phase_patches(half, py, px)
                y = truth[py::2, px::2].astype(np.float64).reshape(-1)
                a, b = a + x.T @ x, b + x.T @ y
            filters[py, px] = np.linalg.solve(a + 1e-6 * np.eye(17), b)
    return filters


def apply_free(filters: dict, half: np.ndarray) -> np.ndarray:
    out = np.empty((2 * half.shape[0], 2 * half.shape[1], half.shape[2]))
    for (py, px), f in filters.items():
        out[py::2, px::2] = (phase_patches(half, py, px) @ f).reshape(half.shape)
    return out


def bench_pairs(spec: str, size: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(XS 2x's image at half ``size``, the 16-spp truth at ``size``) of the bench orbit's scored frames."""
    scene = load_bench_volume(str(DATA / spec))
    pipeline = Pipeline(scene.volume, scene.transfer_function, scale=2, variant="XS", size=(size // 2, size // 2),
                        threads=2)
    cameras = orbit_around(pipeline.caster.visible_bounds(), 12, 2.0)
    pairs = []
    for t, camera in enumerate(tqdm(cameras, desc=spec.split(".")[0], unit="frame")):
        half = pipeline.render(camera)
        if t >= WARMUP:
            pairs.append((half, render_supersampled(pipeline.caster, camera, size, size, spp=16, seed=10**6 + t * 16)))
    return pairs


def bench(args: argparse.Namespace) -> None:
    pairs = {spec.split(".")[0]: bench_pairs(spec, args.size) for spec in VOLUMES}
    names = list(pairs)
    given = [np.array([float(v) for v in k.split(",")]) for k in args.kernel]
    print(f"\n{args.size}², 2°, frames {WARMUP}-11: mean PSNR dB of XS 2x's {args.size // 2}² image doubled\n")
    print("| doubling | " + " | ".join(names) + " |\n|---|" + "---:|" * len(names))
    rows: dict[str, list[str]] = defaultdict(list)
    for name in names:
        others = [p for n in names if n != name and n != "MR_Gd" for p in pairs[n]]
        keys = np.mean([psnr(double(h, KEYS), t) for h, t in pairs[name]])
        rows["Keys, a = -0.75"].append(f"{keys:.2f}")
        w = fit_separable(others)
        rows["separable 4-tap, fitted on the others: gain"].append(
            f"{np.mean([psnr(double(h, w), t) for h, t in pairs[name]]) - keys:+.2f}")
        for label, fitted_on in (("free 4x4 per phase, fitted on the others: gain", others),
                                 ("free 4x4 per phase, fitted on itself: gain", pairs[name])):
            f = fit_free(fitted_on)
            rows[label].append(f"{np.mean([psnr(apply_free(f, h), t) for h, t in pairs[name]]) - keys:+.2f}")
        for k in given:
            rows[f"({', '.join(f'{v:.4f}' for v in k)}): gain"].append(
                f"{np.mean([psnr(double(h, k), t) for h, t in pairs[name]]) - keys:+.2f}")
    for label, cells in rows.items():
        print(f"| {label} | " + " | ".join(cells) + " |")


def videos(args: argparse.Namespace) -> None:
    from volsr_core.dataset.config import read_config
    from volsr_core.dataset.videos import camera_path, load_dataset_volume, plan_videos
    from volsr_core.temporal.ground_truth import ground_truth_frames

    config = read_config(args.config)
    width, height = config.hr_size
    pairs: dict[str, list] = defaultdict(list)
    source = None
    for plan in tqdm(plan_videos(config), desc="videos", unit="video"):
        if source is None or source.name != config.volumes[plan.volume_index].name:
            source = load_dataset_volume(config, plan.volume_index)
        cameras = camera_path(config, source, plan)
        kept = [t >= WARMUP and source.caster.pixels_per_voxel(c, height) >= args.min_pixels_per_voxel
                for t, c in enumerate(cameras)]
        if not any(kept):
            continue
        pipeline = Pipeline(source.volume, source.transfer_function, scale=2, variant="XS",
                            size=(width // 2, height // 2), threads=2)
        truths = ground_truth_frames(source.caster, cameras, width, height, **config.ground_truth)
        for t, (camera, truth) in enumerate(zip(cameras, truths)):
            half = pipeline.render(camera)
            if kept[t]:
                pairs[plan.split].append((half, truth, source.name))
    w = fit_separable([(h, t) for h, t, _ in pairs["train"]])
    print(f"\nfitted on {len(pairs['train'])} train frames (voxels over >= {args.min_pixels_per_voxel:g} output "
          f"pixels): ({', '.join(f'{v:.4f}' for v in w)})\n")
    print("| split | volumes | frames | Keys dB | fitted dB |\n|---|---|---:|---:|---:|")
    for split, rows in pairs.items():
        scores = np.array([[psnr(double(h, k), t) for k in (KEYS, w)] for h, t, _ in rows])
        print(f"| {split} | {', '.join(sorted({n for _, _, n in rows}))} | {len(rows)} | {scores[:, 0].mean():.2f} | "
              f"{scores[:, 1].mean():.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    b = commands.add_parser("bench")
    b.add_argument("--size", type=int, default=1024)
    b.add_argument("--kernel", action="append", default=[], metavar="W0,W1,W2,W3", help="also score this kernel")
    v = commands.add_parser("videos")
    v.add_argument("config")
    v.add_argument("--min-pixels-per-voxel", type=float, default=STRETCH_FROM)
    args = parser.parse_args()
    (bench if args.command == "bench" else videos)(args)


if __name__ == "__main__":
    main()
