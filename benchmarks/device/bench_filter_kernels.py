"""XS's base filter on a GPU, the shipped CUDA kernels against other builds of them: device and host ms, and the
images against the CPU kernel's.

    python benchmarks/device/bench_filter_kernels.py OUT [--size 2048] [--repeats 20] [--compare FILE ...]

For a filter pair (XS 2x: weights (2, 3, 5, 5)) and a single filter (XS 4x: (1, 3, 5, 5)), random weights of those
shapes on a random (size, size, 3) image with values beyond [0, 1]: each build's ``CudaBaseFilter.filter`` is timed
``--repeats`` times in a row (the host's ms a call, and the device's by CUDA events around the batch: the larger of
the two is what a frame pays), each kernel it launches alone (``profile_xs_device.device_ms``), and its image is
compared with the CPU's ``filter_image``. ``--compare`` names other builds of ``base_filter_cuda.py`` to time
beside the shipped one (``git show REV:volsr_core/runtime/base_filter_cuda.py > FILE``). Writes
``OUT/filter_kernels.md``. On the lent H200 (docs/performance-gpu.md, "Seventh lease") a filter-pair call took 0.54
ms against c605e2c's 1.23 at 2048².
"""
from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from numba import cuda

sys.path.insert(0, str(Path(__file__).parent))
from profile_xs_device import LaunchLog, device_ms  # noqa: E402

from volsr_core.runtime import base_filter_cuda  # noqa: E402
from volsr_core.runtime.base_filter import filter_image  # noqa: E402


def timed(name: str, make, weights, bias, image, device_image, repeats: int) -> dict:
    """One build's row: host and device ms a call, each kernel's device ms, the image's difference from the CPU's."""
    built = make(weights, bias)
    got = built.filter(device_image, clip_output=True).copy_to_host()  # compiles
    error = float(np.abs(got - filter_image(image, weights, bias, clip_output=True)).max())
    host, device = [], []
    for _ in range(3):
        cuda.synchronize()
        start, end = cuda.event(), cuda.event()
        start.record()
        began = time.perf_counter()
        for _ in range(repeats):
            built.filter(device_image, clip_output=True)
        host.append(1000.0 * (time.perf_counter() - began) / repeats)
        end.record()
        end.synchronize()
        device.append(start.elapsed_time(end) / repeats)
    with LaunchLog() as log:
        built.filter(device_image, clip_output=True)
    kernels = {kernel: device_ms(launch, repeats) for kernel, _, launch in log.launches}
    return {"build": name, "filters": weights.shape[0], "host_ms": statistics.median(host),
            "device_ms": statistics.median(device), "kernels": kernels, "max_abs_diff": error}


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--size", type=int, default=2048)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--compare", type=Path, nargs="*", default=[])
    args = parser.parse_args(argv)
    builds = []
    for number, path in enumerate(args.compare):
        spec = importlib.util.spec_from_file_location(f"base_filter_cuda_{number}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        builds.append((path.stem, module.CudaBaseFilter))
    builds.append(("shipped", base_filter_cuda.CudaBaseFilter))
    rng = np.random.default_rng(3)
    image = (rng.random((args.size, args.size, 3), dtype=np.float32) * 1.4 - 0.2)
    device_image = cuda.to_device(image)
    rows = []
    for n in (2, 1):
        weights = rng.normal(0.0, 0.2, (n, 3, 5, 5)).astype(np.float32)
        weights[:, :, 2, 2] += 1.0
        bias = rng.normal(0.0, 0.01, (n, 3)).astype(np.float32)
        for name, make in builds:
            rows.append(timed(name, make, weights, bias, image, device_image, args.repeats))
            print(rows[-1], flush=True)
    lines = [f"# XS's base filter on the GPU at {args.size}² (benchmarks/device/bench_filter_kernels.py)", "",
             "| filters | build | host ms a call | device ms a call | kernels (device ms each, alone) | "
             "max abs diff from the CPU |", "|---:|---|---:|---:|---|---:|"]
    for r in rows:
        kernels = ", ".join(f"{k} {v:.3f}" for k, v in r["kernels"].items())
        lines.append(f"| {r['filters']} | {r['build']} | {r['host_ms']:.3f} | {r['device_ms']:.3f} | {kernels} | "
                     f"{r['max_abs_diff']:.2e} |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "filter_kernels.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
