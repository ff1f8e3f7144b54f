"""The U-Nets on the volume's window alone against the whole frame: ms and how far the images differ.

    python benchmarks/bench_content_window.py [--volumes CT_AVM.nii.gz:CT-AAA:0,446,...] [--sizes 512,1024]
                                              [--variants S:2,S:4,M:4,S:8] [--frames 12] [--degrees 2]

For each volume, output size and shipped model (variant:scale) two ``Pipeline`` s render the bench's orbit (ray
starts jittered, 2° a frame), one with ``StatefulUpscaler(skip_background=True)`` (the default), one without, frame
by frame in turn so the machine's phases hit both alike. Printed: the median ms of the step after the render
(``last_timings["network_ms"]``: the TAAU and the network) over the frames after the first four, both ways and
their ratio, the share of the LR frame the window held (median), and the PSNR of the windowed image against the
whole-frame one with the largest difference on any pixel (frames after the first four).
"""
from __future__ import annotations

import argparse
import statistics

import numpy as np
from bench_taau import orbit_scene

from volsr_core.runtime.pipeline import Pipeline

WARMUP = 4
VOLUMES = "CT_AVM.nii.gz:CT-AAA:0,446,LIDC2.mha:CT-Bone:0,255,bonsai.nii.gz:CT-Bone,MR_Gd.nii.gz:MR-Default"


def split_volumes(text: str) -> list[str]:
    """``file:look[:lo,hi]`` specs joined by commas (the window's own comma kept with its spec)."""
    specs: list[str] = []
    for part in text.split(","):
        if specs and part[:1].isdigit():
            specs[-1] += "," + part
        else:
            specs.append(part)
    return specs


def window_share(pipeline: Pipeline) -> float:
    """The share of the last LR frame's pixels the network ran on."""
    top, bottom, left, right = pipeline.upscaler.last_window
    return (bottom - top) * (right - left) / pipeline.last_low_resolution.alpha.size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--volumes", default=VOLUMES)
    parser.add_argument("--sizes", default="512,1024")
    parser.add_argument("--variants", default="S:2,S:4,M:4,S:8")
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--degrees", type=float, default=2.0)
    args = parser.parse_args()
    print("| volume | output | model | ms, window | ms, whole frame | ratio | window share | PSNR dB | max diff |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|")
    for spec in split_volumes(args.volumes):
        scene, _, cameras = orbit_scene(argparse.Namespace(volume=spec, frames=args.frames, degrees=args.degrees))
        for size in (int(s) for s in args.sizes.split(",")):
            for variant, scale in (v.split(":") for v in args.variants.split(",")):
                pipelines = [Pipeline(scene.volume, scene.transfer_function, scale=int(scale), variant=variant,
                                      size=(size, size), threads=2) for _ in range(2)]
                pipelines[1].upscaler.skip_background = False
                ms: list[list[float]] = [[], []]
                shares, psnrs, largest = [], [], 0.0
                for index, camera in enumerate(cameras):
                    images = []
                    for pipeline, times in zip(pipelines, ms):
                        images.append(pipeline.render(camera))
                        times.append(pipeline.last_timings["network_ms"])
                    if index >= WARMUP:
                        shares.append(window_share(pipelines[0]))
                        error = float(np.mean((images[0] - images[1]) ** 2))
                        psnrs.append(10 * np.log10(1.0 / error) if error > 0 else float("inf"))
                        largest = max(largest, float(np.abs(images[0] - images[1]).max()))
                window, whole = (statistics.median(t[WARMUP:]) for t in ms)
                print(f"| {scene.label.split(',')[0]} | {size}² | {variant} {scale}x | {window:.1f} | {whole:.1f} | "
                      f"{window / whole:.2f} | {statistics.median(shares):.2f} | {min(psnrs):.1f} | {largest:.4f} |",
                      flush=True)


if __name__ == "__main__":
    main()
