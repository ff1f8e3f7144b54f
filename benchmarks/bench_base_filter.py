"""Milliseconds per call of VolSR XS's base-filter kernel on TAAU's estimates, optionally side by side with an
earlier commit's.

    python benchmarks/bench_base_filter.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--sizes 512,1024]
                                           [--scales 2,4] [--degrees 2] [--frames 12] [--against COMMIT]
                                           [--stretch 2]

For each output size and scale the LR frames are rendered as ``bench_taau.py`` renders them and run through
``TemporalUpsampler`` once; the TAAU estimates after the first two frames are the inputs. Each goes through
:func:`~volsr_core.runtime.base_filter.filter_image` with the shipped XS model's weights at that scale (a 5x5
pair at 2x, one 5x5 filter at 4x: 9x9 until 2026-11-25), each kernel keeping its :class:`Scratch` as the
upscaler does. With
``--against COMMIT`` the ``volsr_core/runtime/base_filter.py`` of that commit runs too, interleaved call by call
with the current one; the table gives the median ms per call of each, their ratio and the largest difference
between their outputs. ``--stretch 2`` times the filter and the 2x stretch of ``Pipeline(..., stretch=2)`` (XS at half
the output size, ``--sizes`` the filter's): the output clipped and stretched by Keys' cubic (``STRETCH_CUBIC_A``,
clipped) in the filter's own passes where the module's ``filter_image`` takes a ``stretch``, else the filter and then
``resize_bicubic``, as the pipeline did before 2026-11-27.
"""
from __future__ import annotations

import inspect
import statistics
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Callable

import numpy as np
from bench_taau import HISTORY_FRAMES, lr_frames, module_at, orbit_parser, orbit_scene, table_header, table_row

from volsr_core.runtime import base_filter as current
from volsr_core.runtime.engines import OnnxEngine
from volsr_core.runtime.models import model_file
from volsr_core.runtime.upscaler import STRETCH_CUBIC_A
from volsr_core.temporal.resample import resize_bicubic
from volsr_core.temporal.taau import TemporalUpsampler

KERNEL = "volsr_core/runtime/base_filter.py"
ROUNDS = 5  # passes over the estimates


def filter_call(module: ModuleType, stretch: int) -> Callable[[np.ndarray, tuple, object], np.ndarray]:
    """``module``'s filter as ``call(estimate, weights, scratch)``; with ``stretch`` 2 clipped and stretched as the
    upscaler of its time did (decided here, once, not inside the timed calls)."""
    if stretch == 1:
        return lambda estimate, weights, scratch: module.filter_image(estimate, *weights, scratch=scratch)
    if "stretch" in inspect.signature(module.filter_image).parameters:
        return lambda estimate, weights, scratch: module.filter_image(
            estimate, *weights, scratch=scratch, clip_output=True, stretch=stretch, stretch_a=STRETCH_CUBIC_A)

    def filter_then_stretch(estimate: np.ndarray, weights: tuple, scratch) -> np.ndarray:
        image = module.filter_image(estimate, *weights, scratch=scratch, clip_output=True)
        return resize_bicubic(image, stretch * image.shape[1], stretch * image.shape[0], a=STRETCH_CUBIC_A,
                              clamp=(0.0, 1.0))

    return filter_then_stretch


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--stretch", type=int, choices=(1, 2), default=1)
    args = parser.parse_args()
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
                calls = [filter_call(m, args.stretch) for m in modules]
                times: list[list[float]] = [[] for _ in modules]
                difference = 0.0
                for _ in range(ROUNDS):
                    for estimate in estimates:
                        outputs = []
                        for k in range(len(modules)):
                            started = time.perf_counter()
                            outputs.append(calls[k](estimate, weights, scratches[k]))
                            times[k].append(1000.0 * (time.perf_counter() - started))
                        difference = max([difference] + [float(np.abs(o - outputs[0]).max()) for o in outputs[1:]])
                stretched = f" + bicubic {args.stretch}x" if args.stretch > 1 else ""
                print(table_row(f"| {size}² | XS {scale}x{stretched}", [statistics.median(t) for t in times],
                                difference), flush=True)


if __name__ == "__main__":
    main()
