"""What XS 2x's base lacks, split in two: the ray-start noise of one render, and the pixel footprint it samples.

    python benchmarks/probe_noise_split.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--size 1024]

At 1024² VolSR XS 2x lies 0.5-2.0 dB below a noise-free half-size render stretched to the output (16 spp, Keys'
cubic: ``probe_filter_capacity.py``). A 16-spp pixel differs from the 1-spp one XS's TAAU starts from in two ways:
its rays start at 16 offsets along the ray (what the ray-start jitter turns into noise), and they cross 16
positions in the pixel (its footprint, a box filter, where one ray point-samples it). On the bench's orbit (2° a
frame unless ``--degrees``, frames 4-11) this renders the half-size frame four ways, each stretched to ``--size``
by the stretch VolSR uses (Keys' cubic, ``STRETCH_CUBIC_A``), and scores them against the 16-spp truth beside the
shipped XS 2x (``Pipeline``): one ray per pixel centre (ray starts jittered, as every bench render), 16 ray starts
at the pixel centres averaged (the noise gone, the footprint not), one fixed ray start (wood grain instead of
noise), and 16 spp (both gone). Mean PSNR, dB.
"""
from __future__ import annotations

import numpy as np
from bench_taau import orbit_parser, orbit_scene
from probe_stretch_kernel import WARMUP, psnr
from tqdm import tqdm

from volsr_core.render.raycaster import RayCaster
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.runtime.upscaler import STRETCH_CUBIC_A
from volsr_core.temporal import render_supersampled
from volsr_core.temporal.ground_truth import supersampled_truth
from volsr_core.temporal.resample import resize_bicubic

SCALE = 2
STARTS = 16  # ray starts averaged, and samples of the 16-spp frames


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=1024)
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    fixed_start = RayCaster(scene.volume, scene.transfer_function, start_jitter=False)
    xs = Pipeline(scene.volume, scene.transfer_function, scale=SCALE, variant="XS", size=(args.size, args.size),
                  threads=2)
    half = args.size // SCALE

    def stretched(image: np.ndarray) -> np.ndarray:
        return resize_bicubic(image, args.size, args.size, a=STRETCH_CUBIC_A, clamp=(0.0, 1.0))

    labels = ["1 ray a pixel", f"{STARTS} ray starts at the centres", "1 fixed ray start", f"{STARTS} spp",
              "VolSR XS 2x"]
    scores = []
    for t, camera in enumerate(tqdm(cameras, desc=scene.label.split(",")[0], unit="frame")):
        xs_image = xs.render(camera)
        if t < WARMUP:
            continue
        truth = supersampled_truth(caster, camera, t, args.size, args.size)
        seed = 10**5 * (t + 1)
        starts = np.mean([caster.render_color(camera, half, half, seed=seed + k) for k in range(STARTS)], axis=0)
        halves = [caster.render_color(camera, half, half, seed=seed), starts,
                  fixed_start.render_color(camera, half, half),
                  render_supersampled(caster, camera, half, half, spp=STARTS, seed=seed)]
        scores.append([psnr(stretched(image), truth) for image in halves] + [psnr(xs_image, truth)])
    print(f"\n{scene.label}, {args.size}², {args.degrees:g}° a frame, frames {WARMUP}-{len(cameras) - 1}: the "
          f"{half}² render stretched by Keys' cubic, mean PSNR dB\n")
    print("| " + " | ".join(labels) + " |\n|" + "---:|" * len(labels))
    print("| " + " | ".join(f"{v:.2f}" for v in np.mean(scores, axis=0)) + " |")


if __name__ == "__main__":
    main()
