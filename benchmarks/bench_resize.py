"""Milliseconds per call of the bilinear baseline's upscaling (``resize_bilinear``), or with ``--kernel bicubic`` of
VolSR's stretch (``resize_bicubic``, a = -0.75, clamped to [0, 1]), optionally side by side with an earlier commit's.

    python benchmarks/bench_resize.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--sizes 512,1024]
                                      [--factors 2,3,4,6,8] [--degrees 2] [--frames 12] [--against COMMIT]
                                      [--kernel bilinear|bicubic]

For each output size and reduction factor the orbit's frames are rendered at round(size / factor), pixel centres,
as ``volsr bench``'s "native 1/F size + bilinear" renders them, and each is stretched to the output size, five
times over. With ``--against COMMIT`` the ``volsr_core/temporal/resample.py`` of that commit runs too, interleaved
call by call with the current one; the table gives the median ms per call of each, their ratio and the largest
difference between their outputs.
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_taau import module_at, orbit_parser, orbit_scene, table_header, table_row

from volsr_core.temporal import resample as current

KERNEL = "volsr_core/temporal/resample.py"
ROUNDS = 5  # passes over the frames


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--factors", default="2,3,4,6,8")
    parser.add_argument("--kernel", choices=("bilinear", "bicubic"), default="bilinear")
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    with tempfile.TemporaryDirectory() as folder:
        modules = [current] + ([module_at(args.against, Path(folder), KERNEL)] if args.against else [])
        print(f"{scene.label}, {args.frames} frames of {args.degrees:g}°, {ROUNDS} rounds\n")
        print(table_header(f"| output | factor | {args.kernel} ms", args.against))
        for size in (int(s) for s in args.sizes.split(",")):
            for factor in (int(f) for f in args.factors.split(",")):
                lr_size = max(1, round(size / factor))
                frames = [caster.render(camera, lr_size, lr_size, seed=t).color for t, camera in enumerate(cameras)]
                times: list[list[float]] = [[] for _ in modules]
                difference = 0.0
                for _ in range(ROUNDS):
                    for frame in frames:
                        outputs = []
                        for k, module in enumerate(modules):
                            started = time.perf_counter()
                            outputs.append(resize(module, args.kernel, frame, size))
                            times[k].append(1000.0 * (time.perf_counter() - started))
                        difference = max([difference] + [float(np.abs(o - outputs[0]).max()) for o in outputs[1:]])
                print(table_row(f"| {size}² | 1/{factor}", [statistics.median(t) for t in times], difference),
                      flush=True)


def resize(module, kernel: str, frame: np.ndarray, size: int) -> np.ndarray:
    """``frame`` stretched to ``size``² by ``module``'s kernel (an earlier commit's bicubic took no clamp: clipped)."""
    if kernel == "bilinear":
        return module.resize_bilinear(frame, size, size)
    return module.resize_bicubic(frame, size, size, a=-0.75, clamp=(0.0, 1.0))  # clamped in the same pass, as VolSR


if __name__ == "__main__":
    main()
