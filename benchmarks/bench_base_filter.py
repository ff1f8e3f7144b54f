"""Milliseconds per call of VolSR XS's base-filter kernel on TAAU's estimates, optionally side by side with an
earlier commit's.

    python benchmarks/bench_base_filter.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--sizes 512,1024]
                                           [--scales 2,4] [--degrees 2] [--frames 12] [--against COMMIT]

For each output size and scale the LR frames are rendered as ``bench_taau.py`` renders them and run through
``TemporalUpsampler`` once; the TAAU estimates after the first two frames are the inputs. Each goes through
:func:`~volsr_core.runtime.base_filter.filter_image` with the shipped XS model's weights at that scale (a 5x5
pair at 2x, one 5x5 filter at 4x: 9x9 until 2026-11-25), each kernel keeping its :class:`Scratch` as the
upscaler does. With
``--against COMMIT`` the ``volsr_core/runtime/base_filter.py`` of that commit runs too, interleaved call by call
with the current one; the table gives the median ms per call of each, their ratio and the largest difference
between their outputs.
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_taau import HISTORY_FRAMES, lr_frames, module_at, orbit_parser, orbit_scene, table_header, table_row

from volsr_core.runtime import base_filter as current
from volsr_core.runtime.engines import OnnxEngine
from volsr_core.runtime.models import model_file
from volsr_core.temporal.taau import TemporalUpsampler

KERNEL = "volsr_core/runtime/base_filter.py"
ROUNDS = 5  # passes over the estimates


def main() -> None:
    args = orbit_parser(__doc__.split("\n\n")[0]).parse_args()
    scene, caster, cameras = orbit_scene(args)
    with tempfile.TemporaryDirectory() as folder:
        modules = [current] + ([module_at(args.against, Path(folder), KERNEL)] if args.against else [])
        print(f"{scene.label}, {args.frames} frames of {args.degrees:g}°, {ROUNDS} rounds\n")
        print(table_header("| output | model | filter ms", args.against))
        for size in (int(s) for s in args.sizes.split(",")):
            for scale in (int(s) for s in args.scales.split(",")):
                weights = OnnxEngine(model_file("XS", scale)).base_filter
                taau = TemporalUpsampler(scale)
                estimates = [taau(*frame) for frame in lr_frames(caster, cameras, size, scale)][HISTORY_FRAMES:]
                scratches = [m.Scratch() for m in modules]
                times: list[list[float]] = [[] for _ in modules]
                difference = 0.0
                for _ in range(ROUNDS):
                    for estimate in estimates:
                        outputs = []
                        for k, module in enumerate(modules):
                            started = time.perf_counter()
                            outputs.append(module.filter_image(estimate, *weights, scratch=scratches[k]))
                            times[k].append(1000.0 * (time.perf_counter() - started))
                        difference = max([difference] + [float(np.abs(o - outputs[0]).max()) for o in outputs[1:]])
                print(table_row(f"| {size}² | XS {scale}x", [statistics.median(t) for t in times], difference),
                      flush=True)


if __name__ == "__main__":
    main()
