"""Where VolSR XS's time after the LR render goes inside a ``Pipeline``: median ms per frame of the whole step and
of its kernels (TAAU's prepass and kernel, or at 4x and more the layered TAAU's, and the filter; with ``--stretch``
2, XS at half the size, ``Pipeline(..., stretch=2)``, the filter's time holds the bicubic stretch, which it makes
in its own passes).

    python benchmarks/profile_xs_pipeline.py [--volume MR_Gd.nii.gz:MR-Default] [--size 1024] [--scale 2]
                                             [--frames 24] [--stretch 2] [--chunk ROWS]

The pipeline renders an orbit of ``--frames`` frames of 2° each; the first four are not counted (history,
compilation). ``--chunk ROWS`` runs the kernels' parallel loops in chunks of that many iterations that the threads
take as they come (``numba.parallel_chunksize``), where by default each thread takes one equal share. Run it under
different process settings (``OMP_WAIT_POLICY=PASSIVE python ...``) and alternate
the runs to compare them: the machine's noise moves single runs.
"""
from __future__ import annotations

import statistics
import time
from typing import Callable

from bench_taau import orbit_parser, orbit_scene

import numba

import volsr_core.runtime.upscaler as upscaler
import volsr_core.temporal.layered as layered
import volsr_core.temporal.taau as taau
from volsr_core.runtime.pipeline import Pipeline

WARMUP = 4


def timed(module, name: str, times: dict[str, list[float]], chunk: int = 0) -> None:
    """Replace ``module.name`` by a wrapper that appends each call's ms to ``times["module.name"]`` (and runs it with
    ``numba.parallel_chunksize(chunk)``)."""
    function: Callable = getattr(module, name)
    key = f"{module.__name__.rsplit('.', 1)[-1]}.{name}"

    def wrapper(*args, **kwargs):
        started = time.perf_counter()
        with numba.parallel_chunksize(chunk):
            result = function(*args, **kwargs)
        times.setdefault(key, []).append(1000.0 * (time.perf_counter() - started))
        return result

    setattr(module, name, wrapper)


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.set_defaults(volume="MR_Gd.nii.gz:MR-Default", frames=24)
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--scale", type=int, default=2)
    parser.add_argument("--stretch", type=int, default=1, help="XS at 1/k of the size, stretched bicubically by k")
    parser.add_argument("--chunk", type=int, default=0, help="parallel loops in chunks of this many iterations (0: "
                        "one equal share a thread)")
    args = parser.parse_args()
    scene, _, cameras = orbit_scene(args)
    times: dict[str, list[float]] = {}
    for module, name in ((taau, "_prepass"), (taau, "_kernel"), (layered, "_prepass"), (layered, "_kernel"),
                         (upscaler, "filter_image")):
        timed(module, name, times, args.chunk)
    pipeline = Pipeline(scene.volume, scene.transfer_function, scale=args.scale, variant="XS",
                        size=(args.size, args.size), threads=2, stretch=args.stretch)
    step, render = [], []
    for camera in cameras:
        pipeline.render(camera)
        step.append(pipeline.last_timings["network_ms"])
        render.append(pipeline.last_timings["render_ms"])
    after = statistics.median(step[WARMUP:])
    print(f"{scene.label}, {args.size}², XS {pipeline.model_scale}x"
          + (f" in {pipeline.slabs} slabs" if pipeline.slabs else "")
          + (f" + bicubic {args.stretch}x" if args.stretch > 1 else "")
          + (f", chunks of {args.chunk}" if args.chunk else "") + ": LR render "
          f"{statistics.median(render[WARMUP:]):.2f} ms, after it {after:.2f} ms"
          + "".join(f", {name} {statistics.median(ms[WARMUP:]):.2f}" for name, ms in times.items()))


if __name__ == "__main__":
    main()
