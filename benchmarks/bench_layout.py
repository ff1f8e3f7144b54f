"""Milliseconds per frame of the U-Net path's layout work, the layout kernels against the numpy copies they replaced.

    python benchmarks/bench_layout.py [--size 512] [--calls 80]

Per frame the upscaler hands a TAAU-based U-Net its history channels first, (1, 7, H, W) from TAAU's estimate
(H, W, 3) and side outputs (H, W, 4), and turns the network's (3, H, W) output into a clipped (H, W, 3) image.
numpy: ``np.concatenate`` of the parts, ``np.ascontiguousarray`` of its transpose, ``np.clip`` of the output's
transpose (what ``runtime/upscaler.py`` did before commit 289d57f); kernels:
:func:`~volsr_core.runtime.layout.to_channels_first` into a kept buffer and
:func:`~volsr_core.runtime.layout.to_image_clipped`. Random images of an output ``--size``; the two ways called
alternately, medians; the outputs must be equal.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from volsr_core.runtime.layout import to_channels_first, to_image_clipped


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--calls", type=int, default=80)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    parts = [rng.random((args.size, args.size, c), dtype=np.float32) for c in (3, 4)]
    output = rng.normal(0.5, 0.5, (3, args.size, args.size)).astype(np.float32)
    buffer = np.empty((7, args.size, args.size), np.float32)

    def with_numpy() -> tuple[np.ndarray, np.ndarray]:
        history = np.ascontiguousarray(np.concatenate(parts, axis=-1).transpose(2, 0, 1))
        return history, np.clip(output.transpose(1, 2, 0), 0.0, 1.0)

    def with_kernels() -> tuple[np.ndarray, np.ndarray]:
        return to_channels_first(parts, buffer), to_image_clipped(output)

    ways = {"numpy": with_numpy, "kernels": with_kernels}
    results = {name: way() for name, way in ways.items()}  # also the warm-up (numba compiles)
    assert all(np.array_equal(a, b) for a, b in zip(*results.values())), "the two ways differ"
    times: dict[str, list[float]] = {name: [] for name in ways}
    for _ in range(args.calls):
        for name, way in ways.items():
            started = time.perf_counter()
            way()
            times[name].append(1000.0 * (time.perf_counter() - started))
    numpy_ms, kernel_ms = (statistics.median(times[name]) for name in ways)
    print(f"{args.size}² frame, {args.calls} calls each: numpy {numpy_ms:.2f} ms, kernels {kernel_ms:.2f} ms, "
          f"ratio {kernel_ms / numpy_ms:.2f}")


if __name__ == "__main__":
    main()
