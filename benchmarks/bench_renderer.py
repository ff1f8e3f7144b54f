"""VolSR's ray caster vs VTK's vtkFixedPointVolumeRayCastMapper, side by side in one run.

Same volume, transfer function (shaded), camera, image size and sample distance for both;
VolSR also produces every feature buffer (and motion vectors) in the same pass. Renders
alternate between the two so machine noise hits both alike; medians are reported with the
ratio VolSR / VTK. Peak memory is the volume plus the most the renderer allocated (numpy
allocations, traced) while building its tables and rendering, as a multiple of the volume's
float32 size.

    python benchmarks/bench_renderer.py [--data ../shared/data/volumes] [--sizes 128 512]
                                        [--repeats 5] [--diagonal-steps N]
                                        [--out benchmarks/results/renderer.json]

The sample distance is VolSR's default, half the smallest spacing, unless ``--diagonal-steps N``
sets it to the box diagonal / N (the prototypes' "256 steps over the diagonal").
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
import tracemalloc
from pathlib import Path

import numpy as np

from volsr_core.atomic import atomic_write
from volsr_core.render import RayCaster
from volsr_core.scene import Camera, Volume, get_preset

REPO = Path(__file__).resolve().parents[1]

# volume file, preset, value range the preset's design range (HU -1024..3071) is placed on.
# These volumes were rescaled by their publishers (not HU): the ranges put the preset's
# features on the right structures (vessels of CT_AVM, ribs of LIDC2, the bonsai's wood).
SCENES = [
    ("CT_AVM.nii.gz", "CT-AAA", (0.0, 446.0)),
    ("LIDC2.mha", "CT-Bone", (0.0, 255.0)),
    ("bonsai.nii.gz", "CT-Bone", (0.0, 255.0)),
]
VIEWS = [(0.0, 0.0), (60.0, 20.0), (150.0, -15.0)]  # (azimuth, elevation) degrees from the anterior view


def views(volume: Volume) -> list[Camera]:
    start = Camera.framing(volume.bounds).zoom(1.4)
    return [start.azimuth(a).elevation(e).reset_clipping_range(volume.bounds) for a, e in VIEWS]


def peak_memory_ratio(volume: Volume, tf, camera: Camera, size: int, step: float) -> float:
    tracemalloc.start()
    caster = RayCaster(volume, tf, sample_distance=step)
    caster.render(camera, size, size, previous_camera=camera.azimuth(1))
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return (volume.array.nbytes + peak) / volume.array.nbytes


def bench_scene(path: Path, preset: str, value_range, sizes, repeats: int,
                diagonal_steps: int | None) -> list[dict]:
    from volsr_core.hosts.vtk_reference import VtkVolumeRenderer

    volume = Volume.load(path)
    tf = get_preset(preset).placed_on(*value_range)
    step = None
    if diagonal_steps:
        step = float(np.linalg.norm(np.ptp(volume.corners, axis=0))) / diagonal_steps
    caster = RayCaster(volume, tf, sample_distance=step)
    rows = []
    for size in sizes:
        vtk = VtkVolumeRenderer(volume, tf, size, size, mapper="fixed_point", sample_distance=caster.sample_distance)
        ours_ms, vtk_ms = [], []
        for camera in views(volume):
            previous = camera.azimuth(1)
            caster.render(camera, size, size, previous_camera=previous)  # warm-up: compile, caches
            vtk.render(camera)
            for _ in range(repeats):
                t = time.perf_counter()
                caster.render(camera, size, size, previous_camera=previous)
                ours_ms.append(1000 * (time.perf_counter() - t))
                t = time.perf_counter()
                vtk.render(camera)
                vtk_ms.append(1000 * (time.perf_counter() - t))
        vtk.close()
        ours, theirs = statistics.median(ours_ms), statistics.median(vtk_ms)
        rows.append({"volume": path.name, "preset": preset, "size": size, "sample_distance_mm": caster.sample_distance,
                     "volsr_ms": round(ours, 1), "vtk_fixed_point_ms": round(theirs, 1),
                     "ratio": round(ours / theirs, 2),
                     "peak_memory_x_volume": round(peak_memory_ratio(volume, tf, views(volume)[0], size,
                                                                         caster.sample_distance), 2)})
        print(f"{path.name:14s} {size:4d}²  VolSR {ours:7.1f} ms   VTK {theirs:7.1f} ms   ratio {ours / theirs:4.2f}",
              flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data" / "volumes")
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 512])
    parser.add_argument("--repeats", type=int, default=5, help="timed renders per camera view and renderer")
    parser.add_argument("--diagonal-steps", type=int, help="sample distance = box diagonal / N [half the spacing]")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "renderer.json")
    args = parser.parse_args()
    rows = []
    for name, preset, value_range in SCENES:
        rows += bench_scene(args.data / name, preset, value_range, args.sizes, args.repeats, args.diagonal_steps)
    print("\n| volume | size | VolSR ms (all features) | VTK fixed-point ms | ratio | peak memory / volume |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['volume']} | {r['size']}² | {r['volsr_ms']} | {r['vtk_fixed_point_ms']} | {r['ratio']} "
              f"| {r['peak_memory_x_volume']}x |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, "w") as fh:
        json.dump({"benchmark": "renderer", "views": VIEWS, "diagonal_steps": args.diagonal_steps, "rows": rows},
                  fh, indent=2)
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
