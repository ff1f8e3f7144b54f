"""The layered TAAU's clamp under rotation: never, where frames sample finely (the default) and always.

    python benchmarks/probe_layered_clamp.py [--volume engine.nii.gz:MR-Angio:auto] [--size 1024] [--scales 4,2]
                                             [--slabs 2]

The layered TAAU clamps its history into the slab's 3x3 box under a pan or a zoom. While the view rotates it clamped
nowhere until 2026-11-27: on the training videos, mostly at about one output pixel a voxel, the clamp under rotation
threw away more good history than stale (docs/temporal.md, "A shorter history"), while on a shiny look sampled
finely (the engine in MR-Angio at 1024²) the unclamped history keeps the highlights of earlier views; now it clamps
where frames sample finely (``clamp_rotating="fine"``). On the bench's orbit (2° a frame unless ``--degrees``, frames
4-11 against the 16-spp truth) this runs TAAU and the layered TAAU in 2 slabs as shipped, never clamped while
rotating (``"never"``) and always clamped (``"always"``) at each scale, the last also with a shorter history where
frames sample finely (``smooth_count`` 0.25, TAAU's) and with a wider splat (``sigma`` 0.35 LR px, TAAU's), and as
shipped but for TAAU's splat and history length (``sigma`` 0.35, ``cap_angle`` 2/3), and prints each one's mean PSNR
(dB) and its mean colour bias on the object (the signed error per channel where the truth is brighter than 0.05).
``--slabs 1,2`` runs every layered row in one slab and in two.
"""
from __future__ import annotations

import numpy as np
from bench_taau import orbit_parser, orbit_scene
from probe_stretch_kernel import WARMUP, psnr
from tqdm import tqdm

from volsr_core.runtime.methods import Taau
from volsr_core.temporal.ground_truth import supersampled_truth
from volsr_core.temporal.layered import LayeredUpsampler

VARIANTS = {"never clamped while rotating": {"clamp_rotating": "never"},
            "always clamped while rotating": {"clamp_rotating": "always"},
            "always clamped, smooth_count 0.25": {"clamp_rotating": "always", "smooth_count": 0.25},
            "always clamped, sigma 0.35": {"clamp_rotating": "always", "sigma": 0.35},
            "TAAU's sigma 0.35 and cap_angle 2/3": {"sigma": 0.35, "cap_angle": 2.0 / 3.0}}  # LayeredUpsampler settings
OBJECT = 0.05  # truth brighter than this in some channel: the object, not the background


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.set_defaults(volume="engine.nii.gz:MR-Angio:auto", scales="4,2")
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--slabs", default="2", help="the layered rows' depth slabs, comma-separated")
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    shape = (args.size, args.size)
    methods = {}
    for scale in (int(s) for s in args.scales.split(",")):
        methods[f"TAAU {scale}x"] = Taau(caster, shape, scale)
        for slabs in (int(k) for k in args.slabs.split(",")):
            methods[f"TAAU {scale}x in {slabs} slabs"] = Taau(caster, shape, scale, slabs)
            for name, settings in VARIANTS.items():
                variant = Taau(caster, shape, scale, slabs)
                variant.upsampler = LayeredUpsampler(scale, **settings)
                methods[f"TAAU {scale}x in {slabs} slabs, {name}"] = variant
    scores: dict[str, list[float]] = {label: [] for label in methods}
    biases: dict[str, list[np.ndarray]] = {label: [] for label in methods}
    for t, camera in enumerate(tqdm(cameras, desc=scene.label.split(",")[0], unit="frame")):
        images = {label: method(camera).image for label, method in methods.items()}
        if t < WARMUP:
            continue
        truth = supersampled_truth(caster, camera, t, args.size, args.size)
        shown = truth.max(axis=-1) > OBJECT
        for label, image in images.items():
            scores[label].append(psnr(image, truth))
            biases[label].append((np.clip(image, 0.0, 1.0) - truth)[shown].mean(axis=0))
    print(f"\n{scene.label}, {args.size}², {args.degrees:g}° a frame, frames {WARMUP}-{len(cameras) - 1}\n")
    print("| method | PSNR dB | bias on the object, R / G / B |\n|---|---:|---|")
    for label in methods:
        bias = " / ".join(f"{b:+.4f}" for b in np.mean(biases[label], axis=0))
        print(f"| {label} | {np.mean(scores[label]):.2f} | {bias} |")


if __name__ == "__main__":
    main()
