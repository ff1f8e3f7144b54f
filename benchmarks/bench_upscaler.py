"""Milliseconds per frame of ``StatefulUpscaler.upscale`` for a shipped model, on rendered orbit frames, side by side
with an earlier commit's upscaler.

    python benchmarks/bench_upscaler.py --against COMMIT [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--sizes 512,1024]
                                        [--scales 2,4] [--variant S] [--stretch 1] [--degrees 2] [--frames 16]
                                        [--passes 3]

Each frame of the orbit is rendered once, as ``Pipeline`` renders it for the variant's model at that scale (Halton
jitter, the previous camera, the depth slabs the model runs on; ray starts jittered), and goes through the current
``volsr_core/runtime/upscaler.py`` and that of ``COMMIT`` (``git show``), both on the same onnxruntime session,
their order swapped each frame so that machine noise hits both alike. The table gives each one's median ms per
frame (the time after the render: TAAU, the network and the layout around it; the first four frames of a pass
not counted), their ratio and the largest difference between their images; each pass starts both histories afresh.
``--stretch 2`` runs each scale as the model of half of it stretched by 2 (``Pipeline(..., stretch=2)``: "VolSR XS 2x
+ bicubic 2x" at ``--scales 4``).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_taau import module_at, orbit_parser, orbit_scene, table_header, table_row

from volsr_core.runtime import upscaler as current
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.temporal import halton_jitter, jitter_phases

UPSCALER = "volsr_core/runtime/upscaler.py"
WARMUP = 4


def time_side_by_side(pipeline: Pipeline, modules: list, cameras: list, passes: int) -> tuple[list[float], float]:
    """Median ms per ``upscale`` of each module's ``StatefulUpscaler`` (current first) over ``passes`` passes of
    ``cameras``, interleaved frame by frame, and the largest difference between their images."""
    upscalers = [module.StatefulUpscaler(pipeline.engine, slabs=pipeline.slabs, stretch=pipeline.stretch)
                 for module in modules]
    width, height = pipeline.low_resolution_size
    times: list[list[float]] = [[] for _ in modules]
    difference = 0.0
    for _ in range(passes):
        for upscaler in upscalers:
            upscaler.reset()
        previous = None
        for t, camera in enumerate(cameras):
            jitter = halton_jitter(t, jitter_phases(pipeline.model_scale))
            frame = pipeline.caster.render(camera, width, height, jitter=jitter, previous_camera=previous, seed=t,
                                           slabs=pipeline.slabs)
            previous = camera
            images: dict[int, np.ndarray] = {}
            for k in (range(len(modules)) if t % 2 == 0 else reversed(range(len(modules)))):
                started = time.perf_counter()
                images[k] = upscalers[k].upscale(frame, pipeline.caster.background)
                if t >= WARMUP:
                    times[k].append(1000.0 * (time.perf_counter() - started))
            difference = max([difference] + [float(np.abs(images[k] - images[0]).max()) for k in images])
    return [statistics.median(ms) for ms in times], difference


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.set_defaults(frames=16)
    parser.add_argument("--variant", default="S")
    parser.add_argument("--passes", type=int, default=3)
    parser.add_argument("--stretch", type=int, default=1, choices=(1, 2))
    args = parser.parse_args()
    if not args.against:
        parser.error("--against COMMIT is required: the upscaler to compare with")
    scene, _, cameras = orbit_scene(args)
    with tempfile.TemporaryDirectory() as folder:
        modules = [current, module_at(args.against, Path(folder), UPSCALER)]
        print(f"{scene.label}, {args.frames} frames of {args.degrees:g}°, {args.passes} passes\n")
        print(table_header(f"| output | model | upscale ms", args.against))
        for size in (int(s) for s in args.sizes.split(",")):
            for scale in (int(s) for s in args.scales.split(",")):
                pipeline = Pipeline(scene.volume, scene.transfer_function, scale=scale, variant=args.variant,
                                    size=(size, size), threads=2, stretch=args.stretch)
                ms, difference = time_side_by_side(pipeline, modules, cameras, args.passes)
                model = f"{args.variant} {scale // args.stretch}x" + (f" in {pipeline.slabs} slabs" if pipeline.slabs
                                                                     else "")
                model += f" + bicubic {args.stretch}x" if args.stretch > 1 else ""
                print(table_row(f"| {size}² | {model}", ms, difference), flush=True)


if __name__ == "__main__":
    main()
