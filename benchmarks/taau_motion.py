"""TAAU under camera motion against the unjittered reduced-size render + bilinear, scored against 16 spp.

    python benchmarks/taau_motion.py [--volumes CT_AVM,LIDC2,bonsai,MR_Gd] [--size 512] [--scales 2,4]
                                     [--degrees 2] [--path orbit|still] [--frames 16] [--warmup 4]

The four scenes of docs/performance.md (../shared/data), each orbiting ``--frames`` frames of
``--degrees`` from the anterior view that fills the view (``orbit_around``; ``still``: the first of
them held), rendered by the comparison methods of ``volsr_core.runtime.methods`` (ray starts jittered
per frame, as in ``volsr bench``): native 1 spp, native at 1/scale size + bilinear, TAAU, and TAAU without
its fine-sampling smoothing (the bilinear blend and shorter history above 1.75 output px per voxel, what
the networks refine). ``engine`` (MR-Angio) is a fifth scene, held out of every TAAU setting; ``phantom``
is the built-in synthetic one in its default look, ``phantom-AAA`` and ``phantom-bone`` in CT-AAA and
CT-Bone. Mean PSNR over the frames after ``--warmup`` against a 16-spp render of each frame; TAAU's
median ms per call. The tables docs/temporal.md quotes ("TAAU under motion", "Fine sampling") come
from this script.
"""
from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.render import RayCaster
from volsr_core.runtime.methods import Native, ReducedSize, Taau
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.temporal.supersample import render_supersampled
from volsr_core.temporal.taau import TemporalUpsampler

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "volumes"
SCENES = {"CT_AVM": "CT_AVM.nii.gz:CT-AAA:0,446", "LIDC2": "LIDC2.mha:CT-Bone:0,255",
          "bonsai": "bonsai.nii.gz:CT-Bone:auto", "MR_Gd": "MR_Gd.nii.gz:MR-Default:auto",
          "engine": "engine.nii.gz:MR-Angio:auto", "phantom": "phantom", "phantom-AAA": "phantom:CT-AAA",
          "phantom-bone": "phantom:CT-Bone"}


def unsmoothed(method: Taau) -> Taau:
    """``method`` with the fine-sampling smoothing off (no bilinear blend, the full history cap)."""
    method.upsampler = TemporalUpsampler(method.scale, smooth_tent=0.0, smooth_count=1.0)
    return method


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--volumes", default=",".join(SCENES))
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--scales", default="2,4")
    parser.add_argument("--degrees", type=float, default=2.0)
    parser.add_argument("--path", choices=("orbit", "still"), default="orbit")
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--warmup", type=int, default=4)
    args = parser.parse_args()
    size = (args.size, args.size)
    print("| volume | degrees | scale | out px / voxel | native 1 spp | bilinear | TAAU | TAAU - bilinear | "
          "unsmoothed - bilinear | TAAU ms |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.volumes.split(","):
        spec = SCENES[name]
        scene = load_bench_volume(spec if spec.startswith("phantom") else str(DATA / spec))
        caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
        cameras = orbit_around(caster.visible_bounds(), args.frames, args.degrees)
        if args.path == "still":
            cameras = [cameras[0]] * args.frames
        truth = [render_supersampled(caster, c, *size, spp=16, seed=10**6 + 16 * t) for t, c in enumerate(cameras)]

        def mean_psnr(method) -> tuple[float, float]:
            scores, ms = [], []
            for t, camera in enumerate(cameras):
                frame = method(camera)
                if t >= args.warmup:
                    scores.append(psnr_ssim(frame.image, truth[t], channel_axis=-1)[0])
                    ms.append(frame.ms_upscale)
            return statistics.fmean(scores), statistics.median(ms)

        native, _ = mean_psnr(Native(caster, size, 1))
        voxel = caster.render(cameras[0], 8, 8).pixels_per_voxel * args.size / 8  # output px per voxel
        for scale in (int(s) for s in args.scales.split(",")):
            bilinear, _ = mean_psnr(ReducedSize(caster, size, scale, "bilinear"))
            taau, ms = mean_psnr(Taau(caster, size, scale))
            plain, _ = mean_psnr(unsmoothed(Taau(caster, size, scale)))
            print(f"| {name} | {args.degrees:g} | {scale} | {voxel:.2f} | {native:.2f} | {bilinear:.2f} | {taau:.2f} | "
                  f"{taau - bilinear:+.2f} | {plain - bilinear:+.2f} | {ms:.1f} |", flush=True)


if __name__ == "__main__":
    main()
