"""Whether the bench's short orbit understates the temporal methods: VolSR XS's PSNR frame by frame over a longer one.

    python benchmarks/probe_orbit_length.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--size 512] [--frames 48]

``volsr bench`` scores frames 4-11 of a 12-frame orbit; a history that kept improving past frame 11 would make it
unfair to TAAU and the models that refine it. This renders the same orbit (2° a frame unless ``--degrees``) for
``--frames`` frames with the shipped XS 2x and XS 4x (``Pipeline``), the unjittered 1/2- and 1/4-size renders stretched
bilinearly (``ReducedSize``, no history: how hard each block's views are) and the 16-spp truth, and prints the mean
PSNR (dB) over the bench's frames 4-11 and over each later block of 12 frames, and XS's lead over the bilinear
stretch of the same LR size.
"""
from __future__ import annotations

import numpy as np
from bench_taau import orbit_parser, orbit_scene
from probe_stretch_kernel import WARMUP, psnr
from tqdm import tqdm

from volsr_core.runtime.methods import ReducedSize
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.temporal.ground_truth import supersampled_truth

BENCH_FRAMES = 12


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=512)
    parser.set_defaults(frames=48)
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    pipelines = {f"XS {scale}x": Pipeline(scene.volume, scene.transfer_function, scale=scale, variant="XS",
                                          size=(args.size, args.size), threads=2) for scale in (2, 4)}
    for scale in (2, 4):
        pipelines[f"1/{scale} + bilinear"] = ReducedSize(caster, (args.size, args.size), scale)
    scores = []
    for t, camera in enumerate(tqdm(cameras, desc=scene.label.split(",")[0], unit="frame")):
        truth = supersampled_truth(caster, camera, t, args.size, args.size)
        images = [p.render(camera) if isinstance(p, Pipeline) else p(camera).image for p in pipelines.values()]
        scores.append([psnr(image, truth) for image in images])
    scores = np.array(scores)
    scores = np.concatenate([scores, scores[:, :2] - scores[:, 2:]], 1)
    labels = list(pipelines) + ["XS 2x − 1/2 + bilinear", "XS 4x − 1/4 + bilinear"]
    print(f"\n{scene.label}, {args.size}², {args.degrees:g}° a frame: mean PSNR dB\n")
    print("| frames | " + " | ".join(labels) + " |\n|---|" + "---:|" * len(labels))
    blocks = [(WARMUP, BENCH_FRAMES)] + [(a, a + BENCH_FRAMES) for a in range(BENCH_FRAMES, len(cameras), BENCH_FRAMES)]
    for first, end in blocks:
        if end <= len(cameras):
            print(f"| {first}-{end - 1} | " + " | ".join(f"{v:.2f}" for v in scores[first:end].mean(0)) + " |")


if __name__ == "__main__":
    main()
