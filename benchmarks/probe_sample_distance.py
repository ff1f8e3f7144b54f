"""A coarser ray step for every method alike: VolSR XS 4x and the render-smaller + bilinear points around it.

    python benchmarks/probe_sample_distance.py [--volume MR_Gd.nii.gz:MR-Default] [--sizes 1024] [--steps 1,2]
                                               [--degrees 2] [--frames 12]

``volsr bench`` renders every method at the ray caster's default step (half the smallest voxel spacing) and holds
it fixed, as it holds the volumes, motion and ground truth. A step k times as long costs about 1/k of the ray
march and, with the ray starts jittered per frame, leaves noise a temporal method may average away; this measures
what it buys each method on the bench's orbit: VolSR XS 4x (``Pipeline(sample_distance=...)``) and native 1/4 and
1/3 size + bilinear, each at every ``--steps`` multiple of the default, against the bench's 16-spp ground truth at
the default step (medians of ms per frame and mean PSNR over the frames after 4 warm-up frames, all methods
interleaved frame by frame in one process).
"""
from __future__ import annotations

from bench_taau import interleaved, orbit_parser, orbit_scene

from volsr_core.render.raycaster import RayCaster
from volsr_core.runtime.methods import Method, ReducedSize, VolSR
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.temporal import render_supersampled

WARMUP = 4


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.set_defaults(volume="MR_Gd.nii.gz:MR-Default", sizes="1024")
    parser.add_argument("--steps", default="1,2", help="multiples of the default ray step")
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    default_step = caster.sample_distance
    print(f"{scene.label}, {args.frames} frames of {args.degrees:g}°, default step {default_step:g} mm\n")
    print("| output | method | step | ms | PSNR dB |\n|---|---|---:|---:|---:|")
    for size in (int(s) for s in args.sizes.split(",")):
        truth = {t: render_supersampled(caster, camera, size, size, spp=16, seed=10**6 + t * 16)
                 for t, camera in enumerate(cameras) if t >= WARMUP}
        methods: dict[tuple[str, float], Method] = {}
        for k in (float(s) for s in args.steps.split(",")):
            coarse = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign",
                               sample_distance=default_step * k)
            methods[("VolSR XS 4x in 1 or 2 slabs", k)] = VolSR(Pipeline(
                scene.volume, scene.transfer_function, variant="XS", scale=4, size=(size, size),
                sample_distance=default_step * k), "XS")
            methods[("native 1/4 size + bilinear", k)] = ReducedSize(coarse, (size, size), 4)
            methods[("native 1/3 size + bilinear", k)] = ReducedSize(coarse, (size, size), 3)
        row = interleaved(methods, cameras, truth, WARMUP)
        for key in sorted(row):
            print(f"| {size}² | {key[0]} | x{key[1]:g} | {row[key][0]:.1f} | "
                  f"{row[key][1]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
