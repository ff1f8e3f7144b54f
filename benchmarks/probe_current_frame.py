"""What the current LR frame could add to XS's filter beside its base: an upper bound before building it.

    python benchmarks/probe_current_frame.py [--size 512] [--scale 4]   # about a minute at 512², 5 at 1024²; 2 cores

XS filters only its base, TAAU's estimate (at 4x and more the layered TAAU's), where the history and the current
frame are already blended. Issue 12 asks for a network that also sees what TAAU throws away. On the bench's orbit
(12 frames of 2°, frames 4-11 scored against the 16-spp truth, as ``volsr bench``) of the four bench volumes this
captures, per frame, the base the shipped XS model filters (``Pipeline(..., variant="XS")`` at ``--size`` and
``--scale``) and the current frame's own estimate, the same upsampler's with no history (a fresh one each frame:
the splat of the jittered LR samples alone, slab by slab composited at 4x), and fits per colour channel, by least
squares on the *other* volumes' frames (MR_Gd: on the three CTs):

- a 5x5 filter on the base (+ bias): XS's form, fitted here (the bound's own baseline);
- that and a 5x5 filter on the current frame's estimate, summed;
- that and a 3x3 one, or a 1x1 (a weight per channel), on the current frame's estimate.

Fitted on bench frames, these bound what the extra input could give (the probe's gain over its own 5x5 row),
not candidates to ship; the extra filter would cost about what XS's own 5x5 filter costs.
"""
from __future__ import annotations

import argparse

import numpy as np
from bench_taau import DATA
from numpy.lib.stride_tricks import sliding_window_view
from probe_stretch_kernel import VOLUMES, WARMUP, psnr
from tqdm import tqdm

from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.sr.history import HistoryFeed
from volsr_core.temporal.ground_truth import supersampled_truth

RIDGE = 1e-6  # relative to the mean diagonal of the normal matrix, as volsr_core/sr/least_squares.py


def capture(spec: str, size: int, scale: int) -> tuple[list, list, list, list]:
    """Per scored frame: the base the shipped XS model filters, the current frame's estimate without history (both
    clipped to [0, 1], as the filter reads them), the shipped model's image and the 16-spp truth."""
    scene = load_bench_volume(str(DATA / spec))
    pipeline = Pipeline(scene.volume, scene.transfer_function, scale=scale, variant="XS", size=(size, size),
                        threads=2)
    upscaler = pipeline.upscaler
    feed, fresh = upscaler.history, HistoryFeed(upscaler.config, slabs=upscaler.slabs)
    feed_parts = feed.parts
    bases, currents = [], []

    def both(colour, motion, jitter, *args, **kwargs):
        parts = feed_parts(colour, motion, jitter, *args, **kwargs)
        bases.append(np.clip(parts[0], 0.0, 1.0))
        fresh.reset()
        kwargs.pop("out", None)
        currents.append(np.clip(fresh(colour, motion, jitter, *args, **kwargs), 0.0, 1.0))
        return parts

    feed.parts = both  # the feed's __call__ takes its estimate from here
    cameras = orbit_around(pipeline.caster.visible_bounds(), 12, 2.0)
    images = [pipeline.render(camera) for camera in tqdm(cameras, desc=spec.split(".")[0], unit="frame")]
    truths = [supersampled_truth(pipeline.caster, camera, t, size, size) for t, camera in enumerate(cameras)
              if t >= WARMUP]
    return bases[WARMUP:], currents[WARMUP:], images[WARMUP:], truths


def taps(image: np.ndarray, channel: int, kernel: int) -> np.ndarray:
    """(H*W, kernel²) float64: each pixel's kernel x kernel neighbourhood of ``channel``, edges repeated."""
    padded = np.pad(image[..., channel], kernel // 2, mode="edge")
    return sliding_window_view(padded, (kernel, kernel)).reshape(-1, kernel * kernel).astype(np.float64)


def design(base: np.ndarray, current: np.ndarray, channel: int, current_kernel: int) -> np.ndarray:
    """(H*W, unknowns): the base's 5x5 taps, the current estimate's ``current_kernel``² taps (none at 0) and a 1."""
    parts = [taps(base, channel, 5)]
    if current_kernel:
        parts.append(taps(current, channel, current_kernel))
    return np.hstack(parts + [np.ones((base.shape[0] * base.shape[1], 1))])


def normal_equations(frames: list, current_kernel: int) -> tuple[np.ndarray, np.ndarray]:
    """Per channel X^T X and X^T y over ``frames`` (base, current, truth)."""
    unknowns = 26 + current_kernel * current_kernel
    gram, moment = np.zeros((3, unknowns, unknowns)), np.zeros((3, unknowns))
    for base, current, truth in frames:
        for c in range(3):
            x = design(base, current, c, current_kernel)
            gram[c] += x.T @ x
            moment[c] += x.T @ truth[..., c].ravel().astype(np.float64)
    return gram, moment


def solve(gram: np.ndarray, moment: np.ndarray) -> np.ndarray:
    ridge = RIDGE * np.diagonal(gram, axis1=1, axis2=2).mean(1)[:, None, None] * np.eye(gram.shape[1])
    return np.linalg.solve(gram + ridge, moment[..., None])[..., 0]


def apply(weights: np.ndarray, base: np.ndarray, current: np.ndarray, current_kernel: int) -> np.ndarray:
    return np.stack([(design(base, current, c, current_kernel) @ weights[c]).reshape(base.shape[:2])
                     for c in range(3)], -1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--scale", type=int, default=4)
    args = parser.parse_args()
    captured = {spec.split(".")[0]: capture(spec, args.size, args.scale) for spec in VOLUMES}
    names = list(captured)
    shipped = [np.mean([psnr(i, t) for i, t in zip(c[2], c[3])]) for c in captured.values()]
    rows = {}
    for label, kernel in (("5x5 on the base (XS's form)", 0), ("and 5x5 on the current frame", 5),
                          ("and 3x3 on the current frame", 3), ("and 1x1 on the current frame", 1)):
        normals = {n: normal_equations(list(zip(captured[n][0], captured[n][1], captured[n][3])), kernel)
                   for n in tqdm(names, desc=label, unit="volume")}
        rows[label] = []
        for name in names:
            others = [n for n in names if n != name and n != "MR_Gd"]
            weights = solve(sum(normals[n][0] for n in others), sum(normals[n][1] for n in others))
            rows[label].append(np.mean([psnr(np.clip(apply(weights, b, c, kernel), 0.0, 1.0), t) for b, c, t in
                                        zip(captured[name][0], captured[name][1], captured[name][3])]))
    print(f"\n{args.size}², XS {args.scale}x, 2°, frames {WARMUP}-11: mean PSNR dB; filters fitted on the other "
          f"volumes (MR_Gd: the CTs); in brackets the gain over the first fitted row\n")
    print("| filter | " + " | ".join(names) + " |\n|---|" + "---:|" * len(names))
    print("| shipped XS | " + " | ".join(f"{v:.2f}" for v in shipped) + " |")
    first = rows[next(iter(rows))]
    for label, scores in rows.items():
        print(f"| {label} | " + " | ".join(f"{s:.2f} ({s - s0:+.2f})" for s, s0 in zip(scores, first)) + " |")


if __name__ == "__main__":
    main()
