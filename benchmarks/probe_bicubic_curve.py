"""How much of VolSR XS's lead over "render smaller + bilinear" a bicubic stretch of the smaller render would take.

    python benchmarks/probe_bicubic_curve.py [--size 1024] [--degrees 2]   # ~20 min at 1024², 2 cores

The issue's curve, and ``volsr bench``'s, is native 1 spp and native at 1/2 .. 1/8 size stretched bilinearly (what
VTK and 3D Slicer do while interacting). At 1024² a voxel of the bench's volumes spans about three output pixels, a
smaller render is smooth at its pixel scale, and Keys' cubic stretches it closer to the truth than bilinear does.
This runs, side by side as ``volsr bench`` does (``bench_one``: the bench's orbit of 12 frames, frames 4-11 scored
against the 16-spp truth, three timing passes, the methods interleaved frame by frame), native 1 spp, native at the
bench's factors stretched bilinearly and bicubically (``ReducedSize``'s bicubic: Keys' a = -0.5, clamped, the
baseline ``volsr eval`` reports), VolSR XS 2x and VolSR XS 2x + bicubic 2x, on the four bench volumes, and prints
each VolSR point's dB from both curves at its time (the bilinear margin is what ``check_targets`` checks).
"""
from __future__ import annotations

import argparse

from bench_taau import orbit_scene
from probe_stretch_kernel import VOLUMES
from tqdm import tqdm

from volsr_core.apps.bench.report import curve_psnr_at
from volsr_core.apps.bench.run import FACTORS, bench_one
from volsr_core.render.raycaster import RayCaster
from volsr_core.runtime.methods import Native, ReducedSize, VolSR
from volsr_core.runtime.pipeline import Pipeline

FRAMES, WARMUP, PASSES = 12, 4, 3


def methods(scene, caster: RayCaster, size: int) -> list:
    """Fresh methods, in the order every pass runs them."""
    square = (size, size)
    return ([Native(caster, square, 1)]
            + [ReducedSize(caster, square, f, kind) for kind in ("bilinear", "bicubic") for f in FACTORS]
            + [VolSR(Pipeline(scene.volume, scene.transfer_function, scale=scale, variant="XS", size=square, threads=2,
                              stretch=stretch), "XS") for scale, stretch in ((2, 1), (4, 2))])


def margins(rows: list[dict], kind: str) -> dict[str, float]:
    """Each VolSR row's dB above the curve through native 1 spp and the ``kind`` rows, at its time."""
    curve = [r for r in rows if r["method"] == "native" or r["method"] == kind]
    times, psnrs = [r["ms_total"] for r in curve], [r["psnr"] for r in curve]
    return {r["label"]: r["psnr"] - curve_psnr_at(times, psnrs, r["ms_total"]) for r in rows if r["method"] == "volsr"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--degrees", type=float, default=2.0)
    args = parser.parse_args()
    table: dict[str, list[str]] = {}
    names = []
    for spec in VOLUMES:
        scene, caster, cameras = orbit_scene(argparse.Namespace(volume=spec, frames=FRAMES, degrees=args.degrees))
        first = methods(scene, caster, args.size)
        with tqdm(total=FRAMES * (1 + len(first) * PASSES), desc=scene.name, unit="frame") as progress:
            rows = bench_one(scene, caster, (args.size, args.size), first, cameras, warmup=WARMUP, progress=progress,
                             timing_passes=(methods(scene, caster, args.size) for _ in range(PASSES - 1)))
        names.append(scene.name.split(".")[0])
        for row in rows:
            if row["method"] != "native":
                table.setdefault(f"{row['label']}: dB, ms", []).append(f"{row['psnr']:.2f}, {row['ms_total']:.1f}")
        for kind in ("bilinear", "bicubic"):
            for label, margin in margins(rows, kind).items():
                table.setdefault(f"{label}: vs native + {kind} curve", []).append(f"{margin:+.2f}")
    print(f"\n{args.size}², {args.degrees:g}° a frame, frames {WARMUP}-{FRAMES - 1}, {PASSES} timing passes\n")
    print("| | " + " | ".join(names) + " |\n|---|" + "---:|" * len(names))
    for label, cells in table.items():
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
