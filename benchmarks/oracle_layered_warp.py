"""What a history could give under rotation: the exact previous frame, reprojected with exact motion vectors, as
one layer and cut into depth slabs that each move with their own vectors, pulled back or pushed forward.

    python benchmarks/oracle_layered_warp.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--size 512] [--degrees 2]
                                             [--spp 8] [--slabs 1,2,4,8,16]

Two cameras ``--degrees`` apart on the benchmark's orbit. Each frame is rendered with ``--spp`` Halton-jittered
samples per pixel (ray starts jittered, as ``volsr bench`` renders). The previous frame is backward-warped
(``temporal.warp.backward_warp``, bilinear) with the current frame's motion vectors (the renderer's
opacity-threshold point), as TAAU fetches its history; with K slabs the camera's clipping range is cut into K
equal depth slabs, each slab of the previous frame (premultiplied colour and alpha over a black background) is
warped with the vectors of the same slab of the current frame, and the slabs are composited front to back.
"Forward" pushes each slab's pixels instead to where they lie in the current frame (the previous frame's own
vectors towards the current camera, bilinear splats, pixels nothing lands on left empty): a slab's empty
pixels then move nothing, where pulling them back with vectors of the focal plane fetches whatever lay there.
Printed: PSNR (dB) against the current frame of the previous frame unwarped and reprojected each way in each
number of slabs, and, for scale, the bilinear upscale of the current frame's half-size render (``volsr
bench``'s 1/2 size + bilinear). A reprojected history that scores below that cannot lift a temporal upscaler
above the bilinear curve by itself.
"""
from __future__ import annotations

import itertools
from dataclasses import replace

import numba
import numpy as np
from bench_taau import orbit_parser, orbit_scene

from volsr_core.render import RayCaster
from volsr_core.scene.camera import Camera
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.temporal import halton_jitter
from volsr_core.temporal.resample import resize_bilinear
from volsr_core.temporal.warp import backward_warp


def render_rgba(caster: RayCaster, camera: Camera, size: int, spp: int, seed: int = 0) -> np.ndarray:
    """(size, size, 4) premultiplied RGB (over black) and alpha, averaged over ``spp`` Halton-jittered samples
    (ray-start seeds ``seed`` ..)."""
    total = np.zeros((size, size, 4), dtype=np.float64)
    for i in range(spp):
        frame = caster.render(camera, size, jitter=halton_jitter(i, spp), seed=seed + i)
        total[..., :3] += frame.color
        total[..., 3] += frame.alpha
    return (total / spp).astype(np.float32)


@numba.njit(cache=True)
def splat_forward(image: np.ndarray, target: np.ndarray, out: np.ndarray) -> None:
    """Splat each pixel of ``image`` (H, W, C) whose alpha (channel 3) is above 1e-4 at ``target`` (H, W, 2: index
    coordinates in the new view) with bilinear weights into ``out`` (H, W, C + 1), the weights summed in the last
    channel."""
    h, w, channels = image.shape
    out[:] = 0.0
    for y in range(h):
        for x in range(w):
            if image[y, x, 3] <= 1e-4:
                continue
            sx, sy = target[y, x, 0], target[y, x, 1]
            if not (-1.0 < sx < w and -1.0 < sy < h):
                continue
            x0, y0 = int(np.floor(sx)), int(np.floor(sy))
            fx, fy = sx - x0, sy - y0
            for dy in range(2):
                for dx in range(2):
                    xx, yy = x0 + dx, y0 + dy
                    if 0 <= xx < w and 0 <= yy < h:
                        weight = (fx if dx else 1.0 - fx) * (fy if dy else 1.0 - fy)
                        for c in range(channels):
                            out[yy, xx, c] += weight * image[y, x, c]
                        out[yy, xx, channels] += weight


def push_forward(image: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """``image`` (H, W, 4) pushed along ``motion`` (H, W, 2, pixels); where the weights landing on a pixel sum above
    1 they are normalised, below 1 (a hole's edge) they are not, and where nothing lands the pixel is empty."""
    h, w = motion.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w]
    target = np.ascontiguousarray(np.stack([xs, ys], axis=-1) + motion, dtype=np.float64)
    splatted = np.zeros((h, w, image.shape[2] + 1))
    splat_forward(image.astype(np.float64), target, splatted)
    return (splatted[..., :-1] / np.maximum(splatted[..., -1:], 1.0)).astype(np.float32)


def layered_warp(caster: RayCaster, previous: Camera, current: Camera, size: int, spp: int,
                 edges: np.ndarray, forward: bool) -> np.ndarray:
    """The previous frame cut at the depths ``edges`` (mm), each slab reprojected by its own vectors (pulled back
    with the current frame's, or pushed ``forward`` with its own), composited front to back."""
    colour = np.zeros((size, size, 3), dtype=np.float32)
    transmittance = np.ones((size, size, 1), dtype=np.float32)
    for near, far in itertools.pairwise(edges):
        slab = render_rgba(caster, replace(previous, clipping_range=(near, far)), size, spp)
        if forward:
            motion = caster.render(replace(previous, clipping_range=(near, far)), size, previous_camera=current).motion
            warped = push_forward(slab, motion)
        else:
            motion = caster.render(replace(current, clipping_range=(near, far)), size, previous_camera=previous).motion
            warped, _ = backward_warp(slab, np.ascontiguousarray(motion))
        colour += transmittance * warped[..., :3]
        transmittance *= 1.0 - np.clip(warped[..., 3:], 0.0, 1.0)
    return colour


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.set_defaults(frames=6)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--spp", type=int, default=8)
    parser.add_argument("--slabs", default="1,2,4,8,16")
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    previous, current = cameras[-2], cameras[-1]
    near = min(previous.clipping_range[0], current.clipping_range[0])
    far = max(previous.clipping_range[1], current.clipping_range[1])
    size = args.size
    truth = render_rgba(caster, current, size, args.spp, seed=10**6)[..., :3]  # ray starts apart from the rest

    def score(image: np.ndarray) -> str:
        return f"{psnr_ssim(image, truth, channel_axis=-1)[0]:.2f}"

    half = caster.render(current, size // 2, seed=args.spp).color
    print(f"{scene.label}, {size}², {args.degrees:g}° between the frames, {args.spp} spp\n")
    print("| previous frame | PSNR dB against the current one |\n|---|---:|")
    print(f"| current frame's 1/2 size + bilinear (for scale) | {score(resize_bilinear(half, size, size))} |")
    print(f"| unwarped | {score(render_rgba(caster, previous, size, args.spp)[..., :3])} |")
    for forward in (False, True):
        for k in (int(s) for s in args.slabs.split(",")):
            image = layered_warp(caster, previous, current, size, args.spp, np.linspace(near, far, k + 1), forward)
            way = "pushed forward" if forward else "pulled back"
            print(f"| {way}, {k} slab{'s' if k > 1 else ''} | {score(image)} |", flush=True)


if __name__ == "__main__":
    main()
