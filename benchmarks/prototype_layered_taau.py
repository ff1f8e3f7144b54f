"""Prototype (quality only, not speed): temporal upsampling whose history is kept in depth slabs, each slab pushed
forward to the current view by its own pixels' world points, against today's TAAU on the same frames.

    python benchmarks/prototype_layered_taau.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--size 512] [--scale 4]
                                                [--degrees 2] [--frames 12] [--slabs 1,4] [--sigmas 0.35,0.15]
                                                [--caps 1,4]

What ``oracle_layered_warp.py`` found for one exact frame, tried in the loop: the camera's clipping range (the
union over the orbit) is cut into K equal depth slabs; every frame renders each slab at 1/``--scale`` size with
the Halton jitter TAAU uses (here by K clipped renders; the library's ray caster writes the K partial composites
in its one pass: ``RayCaster.render(..., slabs=K)``, and ``benchmarks/bench_layered_taau.py`` measures the library's
layered TAAU). Per slab the HR history holds premultiplied RGBA, its accumulated weight and each pixel's world point
(the pixel's own ray at the view depth of the slab's most opaque sample). Each frame, per slab: the history is
pushed to the new view (bilinear splats of its world points, normalised), brought into the RGBA min/max box of
the slab's 3x3 LR neighbourhood, and blended with the slab's Gaussian splat of its LR samples (``--sigmas``, LR
px) as TAAU blends, its weight capped at ``--caps``; the slabs are composited front to back. K = 1 is the same
algorithm with one layer. Printed: mean PSNR (dB) over the frames after ``--warmup`` against the 16-spp
reference, as ``volsr bench`` scores, of the 1/scale size + bilinear, today's TAAU and each setting; and after
the table, for each K, how many slabs hold something (alpha above 1e-4) per LR pixel that shows something: what
a history pass that skips empty slabs would touch.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numba
import numpy as np
from bench_taau import orbit_parser, orbit_scene
from oracle_layered_warp import splat_forward

from volsr_core.runtime.methods import ReducedSize, Taau
from volsr_core.scene.camera import Camera
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.temporal import halton_jitter, jitter_phases, render_supersampled

HISTORY = 8  # channels of a slab's history: premultiplied RGBA, weight, world point (3)
SPLATTED = 9  # the pushed history's: those, weighted, and the sum of the splat weights


@numba.njit(cache=True)
def blend_slab(pushed, lr, lr_points, scale, jx, jy, inv2s2, cap, eye, forward, rays, history, out):
    """One slab of one frame: the LR slab's (h, w, 4) Gaussian splat estimate, the ``pushed`` history clamped into
    the slab's 3x3 LR box, blended; writes the slab's new ``history`` and its RGBA ``out`` (H, W, 4)."""
    hr_h, hr_w = out.shape[:2]
    lr_h, lr_w = lr.shape[:2]
    estimate = np.zeros(4)
    past = np.zeros(4)
    for y in range(hr_h):
        v = (y + 0.5) / scale - 0.5 - jy
        fy = math.floor(v)
        ly = min(max(int(math.floor(v + 0.5)), 0), lr_h - 1)
        for x in range(hr_w):
            u = (x + 0.5) / scale - 0.5 - jx
            fx = math.floor(u)
            lx = min(max(int(math.floor(u + 0.5)), 0), lr_w - 1)
            estimate[:] = 0.0
            a = 0.0
            for dy in range(2):
                for dx in range(2):
                    yy = min(max(int(fy) + dy, 0), lr_h - 1)
                    xx = min(max(int(fx) + dx, 0), lr_w - 1)
                    weight = math.exp(-((v - fy - dy) ** 2 + (u - fx - dx) ** 2) * inv2s2)
                    a += weight
                    for c in range(4):
                        estimate[c] += weight * lr[yy, xx, c]
            estimate /= a
            landed = pushed[y, x, SPLATTED - 1]
            n = 0.0
            if landed > 1e-3:
                n = min(pushed[y, x, 4] / landed, cap) * min(landed, 1.0)  # a hole's edge holds less
                for c in range(4):
                    lo, hi = 1e30, -1e30
                    for dy in range(-1, 2):
                        for dx in range(-1, 2):
                            value = lr[min(max(ly + dy, 0), lr_h - 1), min(max(lx + dx, 0), lr_w - 1), c]
                            lo, hi = min(lo, value), max(hi, value)
                    past[c] = min(max(pushed[y, x, c] / landed, lo), hi)
            for c in range(4):
                out[y, x, c] = history[y, x, c] = (n * past[c] + a * estimate[c]) / (n + a)
            history[y, x, 4] = min(n + a, cap)
            if lr[ly, lx, 3] > 1e-4 or landed <= 1e-3:  # the pixel's own ray at the slab sample's view depth
                depth = 0.0
                for c in range(3):
                    depth += (lr_points[ly, lx, c] - eye[c]) * forward[c]
                for c in range(3):
                    history[y, x, 5 + c] = eye[c] + depth * rays[y, x, c]
            else:  # the slab shows nothing here now: the point the history brought
                for c in range(3):
                    history[y, x, 5 + c] = pushed[y, x, 5 + c] / landed


def pixel_rays(camera: Camera, size: int) -> np.ndarray:
    """(size, size, 3) directions through the pixel centres of a perspective ``camera``, of unit view depth."""
    right, up, forward = camera.basis()
    half = math.tan(math.radians(camera.view_angle) / 2.0)
    xs = ((np.arange(size) + 0.5) / size * 2.0 - 1.0) * half
    ys = (1.0 - (np.arange(size) + 0.5) / size * 2.0) * half
    return forward + xs[None, :, None] * right + ys[:, None, None] * up


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--scale", type=int, default=4)
    parser.add_argument("--slabs", default="1,4")
    parser.add_argument("--sigmas", default="0.35,0.15")
    parser.add_argument("--caps", default="1,4")
    parser.add_argument("--warmup", type=int, default=4)
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    size, scale = args.size, args.scale
    near = min(c.clipping_range[0] for c in cameras)
    far = max(c.clipping_range[1] for c in cameras)
    truth = [render_supersampled(caster, c, size, size, spp=16, seed=10**6 + 16 * t) for t, c in enumerate(cameras)]

    def score(images: list[np.ndarray]) -> float:
        return float(np.mean([psnr_ssim(image, truth[t], channel_axis=-1)[0]
                              for t, image in enumerate(images) if t >= args.warmup]))

    bilinear, taau = ReducedSize(caster, (size, size), scale), Taau(caster, (size, size), scale)
    print(f"{scene.label}, {size}², {scale}x, {args.degrees:g}° per frame\n")
    print("| method | slabs | sigma (LR px) | cap | PSNR dB |\n|---|---:|---:|---:|---:|")
    print(f"| 1/{scale} size + bilinear | | | | {score([bilinear(c).image for c in cameras]):.2f} |")
    print(f"| TAAU {scale}x (today's) | | | | {score([taau(c).image for c in cameras]):.2f} |", flush=True)
    rays = [pixel_rays(c, size) for c in cameras]
    occupancy: dict[int, float] = {}
    for k in (int(s) for s in args.slabs.split(",")):
        edges = np.linspace(near, far, k + 1)
        frames = []  # per frame, per slab: premultiplied RGBA and the most opaque sample's world point, LR
        for t, camera in enumerate(cameras):
            jitter = halton_jitter(t, jitter_phases(scale))
            slabs = []
            for lo, hi in itertools.pairwise(edges):
                f = caster.render(replace(camera, clipping_range=(lo, hi)), size // scale, jitter=jitter, seed=t)
                slabs.append((np.concatenate([f.color, f.alpha[..., None]], axis=-1).astype(np.float64),
                              np.ascontiguousarray(f.position, dtype=np.float64)))
            frames.append((jitter, slabs))
        occupied = [np.sum([lr[..., 3] > 1e-4 for lr, _ in slabs], axis=0) for _, slabs in frames]
        occupancy[k] = float(np.mean([o[o > 0].mean() for o in occupied]))
        for sigma in (float(s) for s in args.sigmas.split(",")):
            for cap in (float(c) for c in args.caps.split(",")):
                histories: list[np.ndarray | None] = [None] * k
                images = []
                for t, camera in enumerate(cameras):
                    jitter, slabs = frames[t]
                    colour = np.zeros((size, size, 3))
                    transmittance = np.ones((size, size, 1))
                    for i, (lr, points) in enumerate(slabs):
                        pushed = np.zeros((size, size, SPLATTED))
                        if histories[i] is not None:
                            target = camera.world_to_pixel(histories[i][..., 5:8], size, size) - 0.5
                            splat_forward(histories[i], np.ascontiguousarray(target), pushed)
                        history, out = np.zeros((size, size, HISTORY)), np.zeros((size, size, 4))
                        blend_slab(pushed, lr, points, scale, jitter[0], jitter[1], 1.0 / (2.0 * sigma * sigma), cap,
                                   np.asarray(camera.position, dtype=np.float64), camera.basis()[2], rays[t],
                                   history, out)
                        histories[i] = history
                        colour += transmittance * out[..., :3]
                        transmittance *= 1.0 - np.clip(out[..., 3:], 0.0, 1.0)
                    images.append(np.clip(colour, 0.0, 1.0).astype(np.float32))
                print(f"| layered | {k} | {sigma:g} | {cap:g} | {score(images):.2f} |", flush=True)
    print("\n" + ", ".join(f"{k} slabs: {v:.2f} hold something per LR pixel that shows something"
                           for k, v in occupancy.items()))


if __name__ == "__main__":
    main()
