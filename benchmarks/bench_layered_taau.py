"""TAAU with its history in depth slabs (``Taau(..., slabs=K)``), and VolSR XS on it (``Pipeline(..., slabs=K)``),
against today's TAAU, VolSR XS and the native + bilinear curve, side by side on one orbit, as ``volsr bench`` measures
them.

    python benchmarks/bench_layered_taau.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--sizes 512] [--scales 2,4]
                                            [--slabs 2,4] [--degrees 2] [--frames 12] [--stretch 2]
                                            [--model runs/xs2x_layered/volsr-XS-2x.onnx ...]

Every method renders every frame of the orbit (interleaved frame by frame, the ray caster's start jitter on, as
``volsr bench`` renders); PSNR against the 16-spp reference is the mean over the frames after the first four,
times are medians over the same frames. The curve runs through native 1 spp and the 1/2, 1/3, 1/4, 1/6 and 1/8
size + bilinear points (:func:`~volsr_core.apps.bench.report.curve_psnr_at`, the bench's target 2); each TAAU
and VolSR row gives its distance to it at its own time. VolSR rows run the shipped XS model of each scale that has
one (2 threads). ``--stretch 2`` runs those models at half the size, stretched bicubically
(``Pipeline(..., stretch=2)``: "VolSR XS 2x + bicubic 2x" is a 4x point), and leaves out the TAAU rows. Each
``--model`` file (an XS model not shipped, as ``volsr train`` and ``export_onnx`` make it) runs beside them, at its own
scale and the same slab counts, its rows named by the file's folder.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from bench_taau import orbit_parser, orbit_scene

from volsr_core.apps.bench.report import curve_psnr_at
from volsr_core.runtime.methods import Native, ReducedSize, Taau, VolSR
from volsr_core.runtime.models import model_file, shipped_models
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.temporal import render_supersampled

WARMUP = 4
FACTORS = (2, 3, 4, 6, 8)


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.set_defaults(sizes="512")
    parser.add_argument("--slabs", default="2,4")
    parser.add_argument("--stretch", type=int, default=1, help="the XS models at 1/k of the size, stretched by k")
    parser.add_argument("--model", action="append", default=[], type=Path,
                        help="an XS model file to run beside the shipped ones (repeatable)")
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    shipped = {(entry["variant"], int(entry["scale"])) for entry in shipped_models()}
    for size in (int(s) for s in args.sizes.split(",")):
        shape = (size, size)
        truth = [render_supersampled(caster, c, size, size, spp=16, seed=10**6 + 16 * t) for t, c in enumerate(cameras)]
        curve = [Native(caster, shape)] + [ReducedSize(caster, shape, f) for f in FACTORS]
        temporal = [Taau(caster, shape, int(s), k) for s in args.scales.split(",") for k in
                    [0] + [int(k) for k in args.slabs.split(",")] if args.stretch == 1]
        temporal += [VolSR(Pipeline(scene.volume, scene.transfer_function, model_file("XS", int(s), "onnx"),
                                    size=shape, threads=2, slabs=k, stretch=args.stretch), "XS")
                     for s in args.scales.split(",") if ("XS", int(s)) in shipped
                     for k in [0] + [int(k) for k in args.slabs.split(",")]]
        temporal += [VolSR(Pipeline(scene.volume, scene.transfer_function, path, size=shape, threads=2, slabs=k,
                                    stretch=args.stretch), f"XS ({path.parent.name})")
                     for path in args.model for k in [0] + [int(k) for k in args.slabs.split(",")]]
        scores: dict[str, list[float]] = {m.label: [] for m in curve + temporal}
        ms: dict[str, list[tuple[float, float]]] = {m.label: [] for m in curve + temporal}
        for t, camera in enumerate(cameras):
            for method in curve + temporal:
                frame = method(camera)
                if t >= WARMUP:
                    scores[method.label].append(psnr_ssim(frame.image, truth[t], channel_axis=-1)[0])
                    ms[method.label].append((frame.ms_render, frame.ms_upscale))
        psnr = {k: float(np.mean(v)) for k, v in scores.items()}
        total = {k: float(np.median([r + u for r, u in v])) for k, v in ms.items()}
        curve_ms = [total[m.label] for m in curve]
        curve_db = [psnr[m.label] for m in curve]
        print(f"\n{scene.label}, {size}², {args.degrees:g}° per frame\n")
        print("| method | PSNR dB | render ms | upscale ms | total ms | vs curve dB |\n|---|---:|---:|---:|---:|---:|")
        for method in curve + temporal:
            label = method.label
            render, upscale = (float(np.median([p[i] for p in ms[label]])) for i in (0, 1))
            gap = "" if method in curve else f"{psnr[label] - curve_psnr_at(curve_ms, curve_db, total[label]):+.2f}"
            print(f"| {label} | {psnr[label]:.2f} | {render:.1f} | {upscale:.1f} | {total[label]:.1f} | {gap} |",
                  flush=True)


if __name__ == "__main__":
    main()
