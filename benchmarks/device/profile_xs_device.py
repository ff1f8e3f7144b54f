"""Where VolSR XS's step after the render goes on a GPU: the kernels' own time against the host's.

    python benchmarks/device/profile_xs_device.py OUT [--size 2048] [--scale 2] [--names MR_Gd,bonsai]
                                                  [--volumes DIR] [--frames 16] [--repeats 20]

``Pipeline(device="cuda")`` with the shipped XS model renders the bench's orbit (2° a frame) of each named volume;
every kernel numba-cuda launches is recorded with the host's time inside its launch call. Per frame after the
first four (history, compilation), the step after the render (the pipeline's ``network_ms``: from the render's
end, which waits for the GPU, to the image made) is split into the host's time in launch calls and the rest (the
Python around them); then each kernel of the last frame's step is launched again ``--repeats`` times back to back
with its own arguments, CUDA events around the batch: its time a launch on the device, or the launch's own cost
where that is longer (the queue then never fills). Where the device's sum is well below the step, the step is the
host's, and fewer or fused launches are the lever; where it is near the step, the kernels are. Writes
``OUT/profile_xs.md`` (a table per volume) and ``OUT/profile_xs.json``.

On the lent H200 (docs/performance-gpu.md, "Sixth lease") XS 2x's step took 2.7-3.1 ms at 2048² where the
baseline's bilinear stretch took 0.6-1.0; this script's first run ("Seventh lease") found the filter pair's per-pixel
kernel 0.96 ms of the step's 1.4 ms of kernels. Volumes are ``gpu_bench.py pack`` records (``--volumes``); ``--names
phantom`` renders the embedded phantom, and ``NUMBA_ENABLE_CUDASIM=1 ... --names phantom --size 32 --frames 6
--repeats 2`` runs the script in numba's CUDA simulator, to check it, not to time anything.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from gpu_bench import SCENES, read_packed  # noqa: E402

from volsr_core.apps.bench.scenes import load_bench_volume  # noqa: E402
from volsr_core.runtime.pipeline import Pipeline  # noqa: E402
from volsr_core.scene import Volume  # noqa: E402
from volsr_core.scene.camera_paths import orbit_around  # noqa: E402

WARMUP = 4


class LaunchLog:
    """Every kernel launch while installed: (kernel name, host ms in the launch call, the launch to repeat it)."""

    def __init__(self) -> None:
        self.launches: list[tuple[str, float, object]] = []
        from numba import config

        if config.ENABLE_CUDASIM:
            from numba.cuda.simulator.kernel import FakeCUDAKernel as launcher

            self._name = lambda launch: launch.fn.__name__
        else:
            from numba.cuda.dispatcher import _LaunchConfiguration as launcher

            self._name = lambda launch: launch.dispatcher.py_func.__name__
        self._launcher, self._call = launcher, launcher.__call__

    def __enter__(self) -> "LaunchLog":
        original, log = self._call, self

        def call(launch, *args):
            if getattr(launch, "_device", False):  # the simulator calls device functions this way too
                return original(launch, *args)
            started = time.perf_counter()
            result = original(launch, *args)
            log.launches.append((log._name(launch), 1000.0 * (time.perf_counter() - started),
                                 lambda: original(launch, *args)))
            return result

        self._launcher.__call__ = call
        return self

    def __exit__(self, *exc) -> None:
        self._launcher.__call__ = self._call


def device_ms(launch, repeats: int) -> float:
    """ms a launch of ``launch`` takes on the device, timed by CUDA events around ``repeats`` launches in a row."""
    from numba import cuda

    launch()
    cuda.synchronize()
    start, end = cuda.event(), cuda.event()
    start.record()
    for _ in range(repeats):
        launch()
    end.record()
    end.synchronize()
    return max(start.elapsed_time(end), 0.0) / repeats


def profile_volume(name: str, size: int, scale: int, frames: int, repeats: int) -> dict:
    """One volume's frames: the step after the render split into launches and the rest; the last step's kernels."""
    scene = load_bench_volume(None if name == "phantom" else SCENES[name])
    pipeline = Pipeline(scene.volume, scene.transfer_function, scale=scale, variant="XS", size=(size, size),
                        device="cuda")
    cameras = orbit_around(pipeline.caster.visible_bounds(), frames, 2.0)
    steps, in_launches, counts = [], [], []
    with LaunchLog() as log:
        for t, camera in enumerate(cameras):
            log.launches.clear()
            pipeline.render(camera)
            # the step after the render: the launches after the ray cast's
            cast = [i for i, (kernel, _, _) in enumerate(log.launches) if kernel.startswith("_render")]
            after = log.launches[cast[-1] + 1 if cast else 0:]
            if t >= WARMUP:
                steps.append(pipeline.last_timings["network_ms"])
                in_launches.append(sum(ms for _, ms, _ in after))
                counts.append(len(after))
    kernels: dict[str, list[float]] = {}
    for kernel, _, launch in after:
        kernels.setdefault(kernel, []).append(device_ms(launch, repeats))
    step, launched = statistics.median(steps), statistics.median(in_launches)
    return {"volume": name, "size": size, "scale": scale, "frames": len(steps), "step_ms": round(step, 4),
            "launch_calls_ms": round(launched, 4), "other_host_ms": round(step - launched, 4),
            "launches": int(statistics.median(counts)),
            "kernels": {k: {"launches": len(v), "device_ms": round(sum(v), 4)} for k, v in kernels.items()},
            "device_ms": round(sum(sum(v) for v in kernels.values()), 4)}


def markdown(results: list[dict]) -> str:
    lines = ["# VolSR XS's step after the render on the GPU (benchmarks/device/profile_xs_device.py)", ""]
    for r in results:
        lines += [f"## {r['volume']}, {r['size']}², XS {r['scale']}x", "",
                  f"Medians of {r['frames']} frames: the step {r['step_ms']:.3f} ms, of which launch calls "
                  f"{r['launch_calls_ms']:.3f} ms ({r['launches']} launches) and other host work "
                  f"{r['other_host_ms']:.3f} ms; the last step's kernels on the device {r['device_ms']:.3f} ms.", "",
                  "| kernel | launches | device ms |", "|---|---:|---:|"]
        lines += [f"| {k} | {v['launches']} | {v['device_ms']:.3f} |" for k, v in r["kernels"].items()]
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--size", type=int, default=2048)
    parser.add_argument("--scale", type=int, default=2)
    parser.add_argument("--names", default="MR_Gd,bonsai")
    parser.add_argument("--volumes", type=Path, default=Path(__file__).parent / "volumes")
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args(argv)
    unknown = sorted(set(args.names.split(",")) - set(SCENES) - {"phantom"})
    if unknown:
        parser.error(f"--names: no bench volume {', '.join(unknown)} (known: {', '.join(SCENES)}, phantom)")
    Volume.load = read_packed(args.volumes)
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for name in args.names.split(","):
        results.append(profile_volume(name, args.size, args.scale, args.frames, args.repeats))
        (args.out / "profile_xs.json").write_text(json.dumps(results, indent=1))
        (args.out / "profile_xs.md").write_text(markdown(results))
        print(markdown(results[-1:]), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
