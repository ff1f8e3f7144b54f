"""Would rendering finer only where the picture needs it pay? A bound from the bench's own frames.

    python benchmarks/probe_adaptive_tiles.py [--size 512] [--tile 16]   # about a minute at 512², 2 cores

Every method of the bench renders its frame at one size. A renderer could instead cast the 1/4-size frame everywhere
and the 1/2-size rays only in the tiles where the 1/4-size picture falls short. On the bench's orbit (12 frames of
2°, frames 4-11 against the 16-spp truth, as ``volsr bench``) of the four volumes this runs VolSR XS 4x (in 2
slabs) and XS 2x, and per frame pastes XS 2x's image into a share of the ``--tile`` x ``--tile`` tiles of XS 4x's,
chosen two ways:

- *oracle*: the tiles where XS 4x's squared error against the truth is largest (an upper bound: no renderer knows
  the truth);
- *detail*: the tiles where XS 4x's image holds the most detail (its mean absolute difference from its own 3x3
  box blur), something a renderer could know after the 1/4-size pass.

For each share it prints the PSNR and the share of the 1/2-size frame's rays those tiles hold where the volume is
(pixels of the 1/2-size frame with some opacity: the rays that march), beside the curve of the same
run (native 1/4, 1/3 and 1/2 size + bilinear) and both XS points, with their ms. Rays that march cost far more
than those that miss, so the 1/2-size render's ms times that share estimates what the finer tiles add.
"""
from __future__ import annotations

import argparse
import statistics

import numpy as np
from bench_taau import DATA
from probe_stretch_kernel import VOLUMES, WARMUP, psnr
from scipy.ndimage import uniform_filter
from tqdm import tqdm

from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.render import RayCaster
from volsr_core.runtime.methods import ReducedSize, VolSR
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.temporal.ground_truth import supersampled_truth

SHARES = (0.05, 0.1, 0.2, 0.3, 0.5)


def tile_sums(values: np.ndarray, tile: int) -> np.ndarray:
    """(H / tile, W / tile): ``values`` (H, W) summed over each tile."""
    h, w = values.shape
    return values.reshape(h // tile, tile, w // tile, tile).sum(axis=(1, 3))


def paste(coarse: np.ndarray, fine: np.ndarray, chosen: np.ndarray, tile: int) -> np.ndarray:
    """``coarse`` with ``fine``'s pixels in the tiles where ``chosen`` (H / tile, W / tile) is true."""
    mask = np.kron(chosen, np.ones((tile, tile), bool))[..., None]
    return np.where(mask, fine, coarse)


def run_volume(spec: str, size: int, tile: int) -> None:
    scene = load_bench_volume(str(DATA / spec))
    caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
    cameras = orbit_around(caster.visible_bounds(), 12, 2.0)
    curve = [ReducedSize(caster, (size, size), factor) for factor in (4, 3, 2)]
    xs = {scale: VolSR(Pipeline(scene.volume, scene.transfer_function, scale=scale, variant="XS",
                                size=(size, size), threads=2), "XS") for scale in (4, 2)}
    images: dict[str, list] = {}
    ms: dict[str, list] = {}
    truths, marching = [], []
    for t, camera in enumerate(tqdm(cameras, desc=spec.split(".")[0], unit="frame")):
        for method in curve + list(xs.values()):
            frame = method(camera)
            ms.setdefault(method.label, []).append(frame.ms_total)
            if t >= WARMUP:
                images.setdefault(method.label, []).append(frame.image)
        if t >= WARMUP:
            truths.append(supersampled_truth(caster, camera, t, size, size, 16))
            rays = (np.asarray(xs[2].pipeline.last_frame.alpha) > 0.0).astype(np.float64)  # 1/2-size rays that march
            marching.append(np.kron(rays, np.ones((2, 2))))  # on the output's pixels
    mean_ms = {label: statistics.median(v[WARMUP:]) for label, v in ms.items()}
    scores = {label: np.mean([psnr(i, g) for i, g in zip(v, truths)]) for label, v in images.items()}
    print(f"\n{scene.label}, {size}², 2°: " + "; ".join(f"{label} {scores[label]:.2f} dB in {mean_ms[label]:.1f} ms"
                                                   for label in mean_ms))
    four, two = xs[4].label, xs[2].label
    for name in ("oracle", "detail"):
        cells = []
        for share in SHARES:
            psnrs, ray_shares = [], []
            for coarse, fine, truth, rays in zip(images[four], images[two], truths, marching):
                if name == "oracle":
                    score = tile_sums(((coarse - truth) ** 2).sum(-1), tile)
                else:
                    score = tile_sums(np.abs(coarse - uniform_filter(coarse, (3, 3, 1))).sum(-1), tile)
                count = int(round(share * score.size))
                chosen = np.zeros(score.size, bool)
                chosen[np.argsort(score, axis=None)[::-1][:count]] = True
                chosen = chosen.reshape(score.shape)
                psnrs.append(psnr(paste(coarse, fine, chosen, tile), truth))
                ray_shares.append(tile_sums(rays, tile)[chosen].sum() / max(rays.sum(), 1.0))
            cells.append(f"{share:.0%} of tiles: {np.mean(psnrs):.2f} dB, "
                         f"{np.mean(ray_shares):.0%} of the rays that march")
        print(f"  {name}: " + "; ".join(cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--tile", type=int, default=16)
    args = parser.parse_args()
    for spec in VOLUMES:
        run_volume(spec, args.size, args.tile)


if __name__ == "__main__":
    main()
