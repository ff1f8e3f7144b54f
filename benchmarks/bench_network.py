"""GFLOP and milliseconds per frame of the network variants, in onnxruntime (CPU) and PyTorch.

    python benchmarks/bench_network.py [--scale 4] [--size 512] [--previous 2] [--repeats 7]
                                       [--out benchmarks/results/network.json]

GFLOP from torch.utils.flop_counter (2 per multiply-add, convolutions and matrix products);
times are medians, 2 threads, batch 1, the LR input of an HR ``size`` frame.
"""
from __future__ import annotations

import argparse
import io
import json
import statistics
import time
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from volsr_core.atomic import atomic_write
from volsr_core.sr.network import SuperResolutionNet, variant_config

REPO = Path(__file__).resolve().parents[1]


def median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(1000 * (time.perf_counter() - t))
    return statistics.median(times)


def main() -> None:
    import onnxruntime as ort

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scale", type=int, default=4)
    parser.add_argument("--size", type=int, default=512, help="HR output size in pixels")
    parser.add_argument("--previous", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "network.json")
    args = parser.parse_args()
    torch.set_num_threads(2)
    lr_size = args.size // args.scale
    rows = []
    for variant in "SML":
        net = SuperResolutionNet(variant_config(variant, args.scale, args.previous)).eval()
        c = net.config.in_channels
        inputs = (torch.rand(1, args.previous + 1, c, lr_size, lr_size),
                  torch.randn(1, args.previous + 1, 2, lr_size, lr_size), torch.rand(1, args.previous + 1, 2) - 0.5)
        with torch.no_grad(), FlopCounterMode(display=False) as flops:
            reference = net(*inputs).numpy()
        buffer = io.BytesIO()
        torch.onnx.export(net, inputs, buffer, input_names=["lr", "motion", "jitter"], output_names=["hr"],
                          opset_version=17, dynamo=False)
        options = ort.SessionOptions()
        options.intra_op_num_threads = 2
        session = ort.InferenceSession(buffer.getvalue(), options, providers=["CPUExecutionProvider"])
        feed = {"lr": inputs[0].numpy(), "motion": inputs[1].numpy(), "jitter": inputs[2].numpy()}
        difference = float(np.abs(session.run(None, feed)[0] - reference).max())
        with torch.no_grad():
            torch_ms = median_ms(lambda: net(*inputs), args.repeats)
        ort_ms = median_ms(lambda: session.run(None, feed), args.repeats)
        rows.append({"variant": variant, "fold": net.config.fold, "widths": list(net.config.widths),
                     "gflop": round(flops.get_total_flops() / 1e9, 2), "onnxruntime_ms": round(ort_ms, 1),
                     "torch_ms": round(torch_ms, 1), "parameters": sum(p.numel() for p in net.parameters()),
                     "max_abs_difference": difference})
        print(f"{variant}: {rows[-1]['gflop']:6.2f} GFLOP  onnxruntime {ort_ms:6.1f} ms  torch {torch_ms:6.1f} ms",
              flush=True)
    print(f"\n{args.scale}x to {args.size}², {args.previous} previous frames, 2 threads\n")
    print("| variant | fold | U-Net widths | GFLOP | onnxruntime ms | PyTorch ms | parameters |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['variant']} | {r['fold']} | {r['widths']} | {r['gflop']} | {r['onnxruntime_ms']} | "
              f"{r['torch_ms']} | {r['parameters']:,} |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, "w") as fh:
        json.dump({"scale": args.scale, "size": args.size, "previous_frames": args.previous, "rows": rows}, fh, indent=2)


if __name__ == "__main__":
    main()
