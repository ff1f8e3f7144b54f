"""TAAU on a still and an orbiting camera against bilinear upscaling, both scored against 16 spp.

    python benchmarks/taau_motion.py [--size 256] [--scale 2] [--frames 12]

CT_AVM (CT-AAA on 0..446) from ../shared/data: TAAU over the frames, then the last frame's PSNR;
bilinear upscales the last frame's LR render, unjittered (what VTK does) and jittered.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from volsr_core.render import RayCaster
from volsr_core.scene import Camera, Volume, get_preset
from volsr_core.scene.camera_paths import orbit
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.temporal.jitter import halton_jitter, jitter_phases
from volsr_core.temporal.supersample import render_supersampled
from volsr_core.temporal.taau import TemporalUpsampler, resize_bilinear

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "volumes"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--scale", type=int, default=2)
    parser.add_argument("--frames", type=int, default=12)
    args = parser.parse_args()
    volume = Volume.load(DATA / "CT_AVM.nii.gz")
    caster = RayCaster(volume, get_preset("CT-AAA").placed_on(0, 446))
    start, size, lr_size = Camera.framing(volume.bounds), args.size, args.size // args.scale
    for degrees in (0.0, 2.0):
        cameras = orbit(start, args.frames, degrees=args.frames * degrees) if degrees else [start] * args.frames
        taau = TemporalUpsampler(args.scale)
        for t, camera in enumerate(cameras):
            lr = caster.render(camera, lr_size, lr_size, jitter=halton_jitter(t, jitter_phases(args.scale)),
                               previous_camera=cameras[t - 1] if t else None)
            out = taau(lr.color, lr.motion, lr.jitter)
        truth = render_supersampled(caster, cameras[-1], size, size, spp=16)
        unjittered = resize_bilinear(caster.render(cameras[-1], lr_size, lr_size).color, size, size)
        scores = [psnr_ssim(image, truth, channel_axis=-1)[0]
                  for image in (out, unjittered, resize_bilinear(lr.color, size, size))]
        print(f"{degrees:.0f} degrees per frame: TAAU {scores[0]:.2f} dB, bilinear unjittered {scores[1]:.2f} dB, "
              f"bilinear jittered {scores[2]:.2f} dB")


if __name__ == "__main__":
    main()
