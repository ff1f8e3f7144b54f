"""How much a richer local filter on XS's base could add at the bench's sizes: an upper bound before its cost.

    python benchmarks/probe_filter_capacity.py [--size 1024] [--scale 4] [--buckets 8,3,3]   # ~12 min, 2 cores

XS filters its base (TAAU's estimate at 2x, the layered TAAU's at 4x and more) with one 5x5 filter per colour
channel, or at 2x a pair chosen per pixel by orientation. On the bench's orbit (12 frames of 2°, frames 4-11
scored against the 16-spp truth, as ``volsr bench``) of the four bench volumes this captures the base the shipped
model filters (``Pipeline(..., variant="XS")`` at ``--size``, ``--scale``) and scores, per volume:

- the shipped model's image;
- a reference for what the LR frames could carry: the 16-spp render at 1/``--scale`` of the size (noise-free,
  each pixel's box) stretched by Keys' cubic (a = -0.75, as the stretched point);
- least-squares 5x5 filters (+ bias, per channel) fitted on the *other* volumes' frames (MR_Gd: on the three
  CTs), one per pixel class: one class (a single filter), the shipped pair's two orientation classes
  (``second_orientation``), and RAISR-style buckets of the luma's structure tensor (3x3 box): ``--buckets``
  A,S,C angles x strengths (cut at ``--strengths``, luma per pixel) x coherences (evenly cut in [0, 1]).

Fitted on bench frames, these are bounds of what the weights could give, not candidates to ship (that would fit
the method to the benchmark); a class that needs per-pixel weights costs the filter more time, which the curve's
dB per ms prices.
"""
from __future__ import annotations

import argparse

import numpy as np
import torch
from bench_taau import DATA
from numpy.lib.stride_tricks import sliding_window_view
from probe_stretch_kernel import VOLUMES, WARMUP, psnr
from scipy.ndimage import uniform_filter
from tqdm import tqdm

import volsr_core.runtime.upscaler as upscaler
from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.runtime.upscaler import STRETCH_CUBIC_A
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.sr.network import second_orientation
from volsr_core.sr.network_config import ORIENTATION_LUMA
from volsr_core.temporal import render_supersampled
from volsr_core.temporal.resample import resize_bicubic

KERNEL = 5
UNKNOWNS = KERNEL * KERNEL + 1
RIDGE = 1e-6  # relative to the mean diagonal of the pooled normal matrix, as volsr_core/sr/least_squares.py


def capture(spec: str, size: int, scale: int) -> tuple[list, list, list, list]:
    """The bases the shipped XS model filters, its images, the 16-spp truths of the orbit's scored frames and their
    16-spp renders at 1/``scale`` of the size stretched bicubically."""
    scene = load_bench_volume(str(DATA / spec))
    pipeline = Pipeline(scene.volume, scene.transfer_function, scale=scale, variant="XS", size=(size, size),
                        threads=2)
    bases, images, truths, stretched = [], [], [], []
    original = upscaler.filter_image

    def grab(image, *args, **kwargs):
        bases.append(np.clip(image, 0.0, 1.0))
        return original(image, *args, **kwargs)

    upscaler.filter_image = grab
    try:
        for t, camera in enumerate(tqdm(orbit_around(pipeline.caster.visible_bounds(), 12, 2.0),
                                        desc=spec.split(".")[0], unit="frame")):
            image = pipeline.render(camera)
            if t >= WARMUP:
                images.append(image)
                truths.append(render_supersampled(pipeline.caster, camera, size, size, spp=16, seed=10**6 + t * 16))
                small = render_supersampled(pipeline.caster, camera, size // scale, size // scale, spp=16,
                                            seed=10**6 + t * 16)
                stretched.append(resize_bicubic(small, size, size, a=STRETCH_CUBIC_A))
    finally:
        upscaler.filter_image = original
    return bases[WARMUP:], images, truths, stretched


def structure_buckets(base: np.ndarray, angles: int, strengths: np.ndarray, coherences: int) -> np.ndarray:
    """(H*W,) bucket of each pixel: the dominant gradient's angle (of [0, pi)), its strength (sqrt of the larger
    eigenvalue of the 3x3-box structure tensor of the luma, cut at ``strengths``) and coherence."""
    gy, gx = np.gradient(base @ np.asarray(ORIENTATION_LUMA))
    xx, yy, xy = (uniform_filter(v, 3) for v in (gx * gx, gy * gy, gx * gy))
    half_trace = 0.5 * (xx + yy)
    spread = np.sqrt(np.maximum(half_trace ** 2 - (xx * yy - xy * xy), 0.0))
    s1, s2 = np.sqrt(np.maximum(half_trace + spread, 0.0)), np.sqrt(np.maximum(half_trace - spread, 0.0))
    angle = np.minimum((((0.5 * np.arctan2(2 * xy, xx - yy)) % np.pi) / np.pi * angles).astype(int), angles - 1)
    coherence = np.minimum(((s1 - s2) / (s1 + s2 + 1e-12) * coherences).astype(int), coherences - 1)
    return ((angle * (len(strengths) + 1) + np.searchsorted(strengths, s1)) * coherences + coherence).ravel()


def design(base: np.ndarray, channel: int) -> np.ndarray:
    """(H*W, 26) float64: each pixel's 5x5 neighbourhood of ``channel`` (edges repeated) and a 1."""
    padded = np.pad(base[..., channel], KERNEL // 2, mode="edge")
    taps = sliding_window_view(padded, (KERNEL, KERNEL)).reshape(-1, KERNEL * KERNEL)
    return np.hstack([taps, np.ones((len(taps), 1))])


def normal_equations(bases: list, truths: list, classes: list, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Per class and channel, X^T X (count, 3, 26, 26) and X^T y (count, 3, 26) over the frames."""
    gram, moment = np.zeros((count, 3, UNKNOWNS, UNKNOWNS)), np.zeros((count, 3, UNKNOWNS))
    for base, truth, ids in zip(bases, truths, classes):
        order = np.argsort(ids, kind="stable")
        bounds = np.concatenate([[0], np.cumsum(np.bincount(ids, minlength=count))])
        for c in range(3):
            x, y = design(base, c)[order], truth[..., c].ravel()[order].astype(np.float64)
            for k in np.flatnonzero(np.diff(bounds)):
                xk = x[bounds[k]:bounds[k + 1]]
                gram[k, c] += xk.T @ xk
                moment[k, c] += xk.T @ y[bounds[k]:bounds[k + 1]]
    return gram, moment


def solve(gram: np.ndarray, moment: np.ndarray) -> np.ndarray:
    """(count, 3, 26) weights: each class's least squares, drawn by the ridge towards the pooled filter (a class no
    frame had gets that filter)."""
    pooled_gram, pooled_moment = gram.sum(0), moment.sum(0)
    ridge = RIDGE * np.diagonal(pooled_gram, axis1=1, axis2=2).mean(1)[:, None, None] * np.eye(UNKNOWNS)
    pooled = np.linalg.solve(pooled_gram + ridge, pooled_moment[..., None])[..., 0]
    return np.linalg.solve(gram + ridge, (moment + (ridge @ pooled[..., None])[..., 0])[..., None])[..., 0]


def apply(weights: np.ndarray, base: np.ndarray, ids: np.ndarray) -> np.ndarray:
    return np.stack([np.einsum("pu,pu->p", design(base, c), weights[ids, c]).reshape(base.shape[:2])
                     for c in range(3)], -1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--scale", type=int, default=4)
    parser.add_argument("--buckets", default="8,3,3", metavar="A,S,C")
    parser.add_argument("--strengths", default="0.03,0.06", metavar="S1,...")
    args = parser.parse_args()
    angles, strength_count, coherences = (int(v) for v in args.buckets.split(","))
    strengths = np.array([float(v) for v in args.strengths.split(",")])[:strength_count - 1]
    captured = {spec.split(".")[0]: capture(spec, args.size, args.scale) for spec in VOLUMES}
    classifiers = {
        "one filter": (1, lambda base: np.zeros(base.shape[0] * base.shape[1], np.int64)),
        "orientation pair": (2, lambda base: second_orientation(torch.from_numpy(
            np.ascontiguousarray(base.transpose(2, 0, 1)))[None])[0, 0].numpy().astype(np.int64).ravel()),
        f"{angles * strength_count * coherences} structure buckets": (
            angles * strength_count * coherences, lambda base: structure_buckets(base, angles, strengths, coherences)),
    }
    names = list(captured)
    shipped = [np.mean([psnr(i, t) for i, t in zip(images, truths)]) for _, images, truths, _ in captured.values()]
    reference = [np.mean([psnr(s, t) for s, t in zip(stretched, truths)]) for _, _, truths, stretched in
                 captured.values()]
    rows = {}
    for label, (count, classify) in classifiers.items():
        classes = {n: [classify(b) for b in captured[n][0]] for n in names}
        normals = {n: normal_equations(captured[n][0], captured[n][2], classes[n], count) for n in names}
        rows[label] = []
        for name in names:
            others = [n for n in names if n != name and n != "MR_Gd"]
            weights = solve(*(sum(normals[n][i] for n in others) for i in (0, 1)))
            rows[label].append(np.mean([psnr(apply(weights, b, k), t) for b, k, t in
                                        zip(captured[name][0], classes[name], captured[name][2])]))
    print(f"\n{args.size}², XS {args.scale}x, 2°, frames {WARMUP}-11: mean PSNR dB; 5x5 filters fitted on the other "
          f"volumes (MR_Gd: the CTs), gain over the shipped model\n")
    print("| filter on the base | " + " | ".join(names) + " |\n|---|" + "---:|" * len(names))
    print("| shipped | " + " | ".join(f"{v:.2f}" for v in shipped) + " |")
    print(f"| 16-spp render at 1/{args.scale} size + bicubic (a reference) | "
          + " | ".join(f"{s:.2f} ({s - s0:+.2f})" for s, s0 in zip(reference, shipped)) + " |")
    for label, scores in rows.items():
        print(f"| {label} | " + " | ".join(f"{s:.2f} ({s - s0:+.2f})" for s, s0 in zip(scores, shipped)) + " |")


if __name__ == "__main__":
    main()
