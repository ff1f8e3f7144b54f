"""Where a 4x history should live at 1024²: at the output size, or at half of it and stretched.

    python benchmarks/probe_history_size.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--sizes 1024] [--degrees 2]
                                            [--frames 12] [--bicubic-curve]

At 1024² the bench volumes span about three output pixels per voxel, and VolSR XS 4x keeps its layered history and
runs its filter on every one of them (the step after the render costs 15-30 ms there on two cores). The same 1/4-size
jittered render can instead feed VolSR XS 2x at half the output size (its TAAU 2x and filter on a quarter of the
pixels), whose image is then stretched to the full size (bicubic, as ``Pipeline(..., stretch=2)`` does). This runs
both beside native 1/4, 1/3 and 1/2 size + bilinear, all interleaved frame by frame in one process, and gives each
VolSR row's distance to that curve at equal time (medians of ms per frame and mean PSNR over the frames after 4
warm-up frames, against the bench's 16-spp ground truth). With ``--bicubic-curve`` the same reduced renders stretched
bicubically (Keys, a = -0.5, clamped: what a viewer could do with its own reduced render, as VolSR's stretch does with
its image) run too, and each VolSR row's distance to that curve is given beside.
"""
from __future__ import annotations

from bench_taau import interleaved, orbit_parser, orbit_scene

from volsr_core.apps.bench.report import curve_psnr_at
from volsr_core.runtime.methods import Method, ReducedSize, VolSR
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.temporal import render_supersampled

WARMUP = 4


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.set_defaults(sizes="1024")
    parser.add_argument("--bicubic-curve", action="store_true", help="also native 1/4, 1/3, 1/2 size + bicubic")
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    print(f"{scene.label}, {args.frames} frames of {args.degrees:g}°\n")
    kinds = ("bilinear", "bicubic") if args.bicubic_curve else ("bilinear",)
    print("| output | method | ms | PSNR dB | " + " | ".join(f"dB from the {kind} curve" for kind in kinds) + " |\n"
          "|---|---|---:|---:|" + "---:|" * len(kinds))
    for size in (int(s) for s in args.sizes.split(",")):
        truth = {t: render_supersampled(caster, camera, size, size, spp=16, seed=10**6 + t * 16)
                 for t, camera in enumerate(cameras) if t >= WARMUP}
        methods: dict[str, Method] = {}
        for k in (1, 2):  # VolSR XS 4x in 1 or 2 slabs, VolSR XS 2x + bicubic 2x
            method = VolSR(Pipeline(scene.volume, scene.transfer_function, variant="XS", scale=4, size=(size, size),
                                    stretch=k), "XS")
            methods[method.label] = method
        curves = {kind: {f"native 1/{f} size + {kind}": ReducedSize(caster, (size, size), f, kind) for f in (4, 3, 2)}
                  for kind in kinds}
        row = interleaved({**methods, **{k: m for curve in curves.values() for k, m in curve.items()}}, cameras, truth,
                          WARMUP)
        for key in row:
            margins = [f"{row[key][1] - curve_psnr_at(*zip(*(row[k] for k in curve)), row[key][0]):+.2f}"
                       if key in methods else "" for curve in curves.values()]
            print(f"| {size}² | {key} | {row[key][0]:.1f} | {row[key][1]:.2f} | {' | '.join(margins)} |", flush=True)


if __name__ == "__main__":
    main()
