"""GFLOP and milliseconds per frame of the network variants, in onnxruntime (CPU) and PyTorch.

    python benchmarks/bench_network.py [--scale 4] [--size 512] [--repeats 7]
                                       [--out benchmarks/results/network.json]

Four configurations of each variant S, M, L: the paper's (N = 2 previous frames), recurrent
(N = 0, the warped previous output as history), TAAU-based (N = 0, refining TAAU's estimate) and
TAAU-based with TAAU's side outputs as inputs too (`taau_aux`: the shipped models; TAAU itself runs
before the network and is timed by `volsr bench`).
GFLOP from torch.utils.flop_counter (2 per multiply-add, convolutions and matrix products);
times are medians, 2 threads, batch 1, the LR input of an HR ``size`` frame, the ONNX graph as
volsr_core.runtime.export writes it.
"""
from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from volsr_core.atomic import atomic_write
from volsr_core.runtime.engines import OnnxEngine
from volsr_core.runtime.export import example_inputs, export_onnx
from volsr_core.sr.network import SuperResolutionNet, variant_config

REPO = Path(__file__).resolve().parents[1]
CONFIGURATIONS = {"paper (N=2)": {"previous_frames": 2}, "recurrent (N=0)": {"previous_frames": 0, "recurrent": True},
                  "TAAU-based (N=0)": {"previous_frames": 0, "taau_base": True},
                  "TAAU-based + side outputs (N=0)": {"previous_frames": 0, "taau_base": True, "taau_aux": True}}


def median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(1000 * (time.perf_counter() - t))
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scale", type=int, default=4)
    parser.add_argument("--size", type=int, default=512, help="HR output size in pixels")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "network.json")
    args = parser.parse_args()
    torch.set_num_threads(2)
    lr_size = args.size // args.scale
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, options in CONFIGURATIONS.items():
            for variant in "SML":
                net = SuperResolutionNet(variant_config(variant, args.scale, **options)).eval()
                inputs = example_inputs(net.config, lr_size, lr_size)
                with torch.no_grad(), FlopCounterMode(display=False) as flops:
                    reference = net(*inputs).numpy()
                engine = OnnxEngine(export_onnx(net, Path(tmp) / "m.onnx"), providers=["CPUExecutionProvider"],
                                    threads=2)
                feed = [x.numpy() for x in inputs]
                difference = float(np.abs(engine(*feed) - reference).max())
                with torch.no_grad():
                    torch_ms = median_ms(lambda: net(*inputs), args.repeats)
                ort_ms = median_ms(lambda: engine(*feed), args.repeats)
                rows.append({"configuration": name, "variant": variant, "fold": net.config.fold,
                             "widths": list(net.config.widths), "gflop": round(flops.get_total_flops() / 1e9, 2),
                             "onnxruntime_ms": round(ort_ms, 1), "torch_ms": round(torch_ms, 1),
                             "parameters": sum(p.numel() for p in net.parameters()), "max_abs_difference": difference})
                print(f"{name:17s} {variant}: {rows[-1]['gflop']:6.2f} GFLOP  onnxruntime {ort_ms:6.1f} ms  "
                      f"torch {torch_ms:6.1f} ms", flush=True)
    print(f"\n{args.scale}x to {args.size}², 2 threads\n")
    print("| configuration | variant | fold | U-Net widths | GFLOP | onnxruntime ms | PyTorch ms | parameters |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['configuration']} | {r['variant']} | {r['fold']} | {r['widths']} | {r['gflop']} | "
              f"{r['onnxruntime_ms']} | {r['torch_ms']} | {r['parameters']:,} |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, "w") as fh:
        json.dump({"scale": args.scale, "size": args.size, "rows": rows}, fh, indent=2)


if __name__ == "__main__":
    main()
