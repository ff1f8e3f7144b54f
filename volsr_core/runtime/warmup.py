"""Compile VolSR's numba kernels into numba's disk cache before a first frame needs them.

Numba compiles a kernel the first time it runs with a given type signature and keeps the machine code in its disk
cache (``cache=True``: beside the package, or in the user's cache folder where that is read-only), so each kernel
compiles once per install: the ray caster's colour and feature programs, TAAU, the layered TAAU, XS's filters and the
resampling, about a minute on two cores (64 s on the machine of 2026-11-27). Without this a host's first VolSR frame
waits that long with nothing to say why (3D Slicer's view freezes). :func:`compile_kernels` runs each path a host or
command takes, on a small phantom, so that the cache holds the signatures those take; with the cache filled it takes
a fraction of a second (`volsr warmup`, and 3D Slicer's module once per session before VolSR's first frame).
"""
from __future__ import annotations

import time
from typing import Callable

from volsr_core.io import make_phantom
from volsr_core.render import RayCaster
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene import Camera, Volume, get_preset

FRAMES = 3  # a first frame (a cut: no motion, no history), then two that follow it: every path a frame takes


def _pipeline_frames(volume: Volume, variant: str = "XS", **settings) -> None:
    """A few frames of an orbit through ``Pipeline(volume, CT-Phantom, variant=variant, **settings)``."""
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), variant=variant, threads=1, **settings)
    camera = Camera.framing(volume.bounds)
    for frame in range(FRAMES):
        pipeline.render(camera.azimuth(2.0 * frame))


def kernel_paths(volume: Volume) -> list[tuple[str, Callable[[], None]]]:
    """(what it compiles, a call that runs it) for each path: native rendering's colour program, VolSR XS as hosts
    run it by default at 2x, at 4x (two depth slabs) and stretched (XS 2x at half the size, bicubic), and a U-Net
    model (its TAAU's side outputs, the layouts between images and the network)."""
    camera = Camera.framing(volume.bounds)
    return [
        ("ray caster, colour program (native rendering)",
         lambda: RayCaster(volume, get_preset("CT-Phantom"), start_jitter="ign").render_color(camera, 16, 16)),
        ("VolSR XS 2x: feature program, TAAU, filter pair", lambda: _pipeline_frames(volume, scale=2, size=(32, 32))),
        ("VolSR XS 4x: depth slabs, layered TAAU, filter", lambda: _pipeline_frames(volume, scale=4, size=(64, 64))),
        ("VolSR XS 2x stretched 2x: bicubic resampling",
         lambda: _pipeline_frames(volume, scale=4, stretch=2, size=(64, 64))),
        ("VolSR S 4x: TAAU's side outputs, network layouts",
         lambda: _pipeline_frames(volume, variant="S", scale=4, size=(64, 64))),
    ]


def compile_kernels(progress: bool = False) -> list[tuple[str, float]]:
    """Run every path of :func:`kernel_paths` once (compiling what numba's disk cache does not hold yet); returns
    (path, seconds) for each. ``progress`` shows a bar (tqdm) naming the path being compiled."""
    from tqdm import tqdm

    volume = Volume.from_record(make_phantom(shape=(24, 24, 24)))
    timings = []
    paths = kernel_paths(volume)
    with tqdm(paths, desc="compiling", unit="path", disable=not progress) as bar:
        for name, run in bar:
            bar.set_postfix_str(name.split(":")[0])
            started = time.perf_counter()
            run()
            timings.append((name, time.perf_counter() - started))
    return timings
