"""Where ``stretch="auto"`` should switch from XS 4x to XS 2x stretched as the view turns faster: the sweep behind
``FAST_TURN`` (docs/performance.md, "How fast the view turns").

    python benchmarks/probe_stretch_speed.py [--sizes 256,512] [--degrees 2,3,4,5] [--out out/stretch_speed]
                                             # ~15 min, 2 cores

For each bench volume, output size and speed (an orbit of 12 frames of that many degrees, frames 4-11 against the
16-spp truth, as ``volsr bench``) it runs VolSR XS 4x in 2 slabs and XS 2x + bicubic 2x beside native 1/4, 1/3 and
1/2 size + bilinear, interleaved frame by frame (``probe_history_size.py``'s runs), and gives each VolSR row's
distance to that curve. Then it scores choosing between the two by a rule, over every point: what the rule gives
up against the better of the two (summed, and the most at one point), for ``Pipeline``'s rule (the turn times the
view's output pixels per voxel from ``FAST_TURN[1]``), a plain 3° rule and the two fixed choices. Writes
``stretch_speed.md`` and ``stretch_speed.png`` (the stretched row's lead over XS 4x against the turn times the
pixels per voxel, the rule's threshold marked) under ``--out``.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib
import numpy as np
from bench_taau import DATA, REPO, interleaved
from probe_stretch_kernel import VOLUMES
from tqdm import tqdm

from volsr_core.apps.bench.report import curve_psnr_at
from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.atomic import atomic_write
from volsr_core.render import RayCaster
from volsr_core.runtime.methods import ReducedSize, VolSR
from volsr_core.runtime.pipeline import FAST_TURN, Pipeline
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.temporal.ground_truth import supersampled_truth

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 - after the backend is chosen

WARMUP = 4
LAYERED, STRETCHED = "VolSR XS 4x in 1 or 2 slabs", "VolSR XS 2x + bicubic 2x"


def margins(spec: str, size: int, degrees: float) -> tuple[float, float, float]:
    """(pixels per voxel of the orbit's first view at ``size``, XS 4x's and the stretched point's dB from the curve)."""
    scene = load_bench_volume(str(DATA / spec))
    caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
    cameras = orbit_around(caster.visible_bounds(), 12, degrees)
    truth = {t: supersampled_truth(caster, camera, t, size, size) for t, camera in enumerate(cameras) if t >= WARMUP}
    volsr = {}
    for stretch in (1, 2):
        method = VolSR(Pipeline(scene.volume, scene.transfer_function, variant="XS", scale=4, size=(size, size),
                                stretch=stretch), "XS")
        volsr[method.label] = method
    curve = {f"native 1/{f} size + bilinear": ReducedSize(caster, (size, size), f) for f in (4, 3, 2)}
    row = interleaved({**volsr, **curve}, cameras, truth, WARMUP)
    times, psnrs = zip(*(row[key] for key in curve))
    return (caster.pixels_per_voxel(cameras[0], size),
            *(row[key][1] - curve_psnr_at(times, psnrs, row[key][0]) for key in (LAYERED, STRETCHED)))


def given_up(points: list[dict], stretches) -> tuple[float, float]:
    """(summed, most) dB a choice ``stretches(point)`` gives up against the better of the two rows over ``points``."""
    lost = [max(p["layered"], p["stretched"]) - (p["stretched"] if stretches(p) else p["layered"]) for p in points]
    return float(np.sum(lost)), float(np.max(lost))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="256,512")
    parser.add_argument("--degrees", default="2,3,4,5")
    parser.add_argument("--out", type=Path, default=REPO / "out" / "stretch_speed")
    args = parser.parse_args()
    runs = [(spec, int(size), float(degrees)) for spec in VOLUMES for size in args.sizes.split(",")
            for degrees in args.degrees.split(",")]
    points = []
    for spec, size, degrees in tqdm(runs, desc="orbits", unit="orbit"):
        per_voxel, layered, stretched = margins(spec, size, degrees)
        points.append({"volume": spec.split(".")[0], "size": size, "degrees": degrees, "per_voxel": per_voxel,
                       "layered": layered, "stretched": stretched})
    rules = {f"the turn times the pixels per voxel ≥ {FAST_TURN[1]:g} (Pipeline's)":
             lambda p: p["degrees"] * p["per_voxel"] >= FAST_TURN[1],
             "the turn ≥ 3°": lambda p: p["degrees"] >= 3.0,
             "never stretched": lambda p: False, "always stretched": lambda p: True}
    lines = ["| volume | size | degrees a frame | pixels per voxel | XS 4x in 2 slabs, dB from the curve | "
             "XS 2x + bicubic 2x | the stretch's lead |", "|---|---:|---:|---:|---:|---:|---:|"]
    lines += [f"| {p['volume']} | {p['size']}² | {p['degrees']:g} | {p['per_voxel']:.2f} | {p['layered']:+.2f} | "
              f"{p['stretched']:+.2f} | {p['stretched'] - p['layered']:+.2f} |" for p in points]
    lines += ["", "| choosing by | dB given up, summed | the most at one point |", "|---|---:|---:|"]
    lines += [f"| {name} | {total:.2f} | {most:.2f} |" for name, (total, most) in
              ((name, given_up(points, rule)) for name, rule in rules.items())]
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out / "stretch_speed.md", "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    figure, axes = plt.subplots(figsize=(7, 4.5))
    for size, marker in zip(sorted({p["size"] for p in points}), "os^"):
        for volume, colour in zip(sorted({p["volume"] for p in points}), ("C0", "C1", "C2", "C3")):
            chosen = [p for p in points if p["size"] == size and p["volume"] == volume]
            axes.plot([p["degrees"] * p["per_voxel"] for p in chosen], [p["stretched"] - p["layered"] for p in chosen],
                      marker=marker, color=colour, label=f"{volume}, {size}²")
    axes.axhline(0.0, color="grey", lw=0.8)
    axes.axvline(FAST_TURN[1], color="black", ls="--", lw=1, label=f"stretched from {FAST_TURN[1]:g}")
    axes.axvline(FAST_TURN[0], color="black", ls=":", lw=1, label=f"... until below {FAST_TURN[0]:g}")
    axes.set_xlabel("degrees a frame × output pixels per voxel")
    axes.set_ylabel("XS 2x + bicubic 2x − XS 4x in 2 slabs, dB")
    axes.set_title("Each against the native + bilinear curve: the stretch's lead as the view turns", fontsize=10)
    axes.legend(fontsize=7, ncol=2)
    figure.tight_layout()
    with atomic_write(args.out / "stretch_speed.png", "wb") as fh:
        figure.savefig(fh, format="png", dpi=120)
    print(f"wrote {args.out / 'stretch_speed.md'} and {args.out / 'stretch_speed.png'}")


if __name__ == "__main__":
    main()
