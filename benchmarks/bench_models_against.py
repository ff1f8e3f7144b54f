"""Milliseconds per call of the shipped ONNX models in onnxruntime, side by side with the same files at an earlier
commit (a re-export after a rewrite of the graph), and the largest difference between their outputs.

    python benchmarks/bench_models_against.py --against COMMIT [--size 512] [--calls 25] [NAME ...]

Both sessions as the runtime makes them (:class:`~volsr_core.runtime.engines.OnnxEngine`'s options: 2 intra-op
threads, no spinning), fed the same random inputs of an output ``--size`` frame (the LR frame at the model's
scale, TAAU's history at full size), called alternately so that machine noise hits both alike; medians. Models
whose file did not change are skipped. By default every U-Net model in ``resources/models/models.json``.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from volsr_core.runtime.engines import OnnxEngine
from volsr_core.runtime.export import example_inputs, input_names

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "resources" / "models"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*")
    parser.add_argument("--against", required=True, metavar="COMMIT")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--calls", type=int, default=25)
    args = parser.parse_args()
    registry = json.loads((MODELS / "models.json").read_text())["models"]
    entries = [m for m in registry if (m["name"] in args.names if args.names else m["variant"] != "XS")]
    print(f"{args.size}² output, {args.calls} calls each, alternating\n")
    print(f"| model | ms | {args.against} ms | ratio | max difference |\n|---|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as folder:
        for entry in entries:
            path = MODELS / entry["files"]["onnx"]
            old = Path(folder) / path.name
            old.write_bytes(subprocess.run(["git", "-C", str(REPO), "show", f"{args.against}:{path.relative_to(REPO)}"],
                                           check=True, capture_output=True).stdout)
            if old.read_bytes() == path.read_bytes():
                continue
            engines = [OnnxEngine(path, threads=2), OnnxEngine(old, threads=2)]
            config = engines[0].config
            lr = args.size // config.scale
            inputs = dict(zip(input_names(config), (t.numpy() for t in example_inputs(config, lr, lr))))
            sessions = [(e.session, {i.name: inputs[i.name] for i in e.session.get_inputs()}) for e in engines]
            outputs = [session.run(None, feed)[0] for session, feed in sessions]  # also the warm-up call
            times: list[list[float]] = [[], []]
            for _ in range(args.calls):
                for k, (session, feed) in enumerate(sessions):
                    started = time.perf_counter()
                    session.run(None, feed)
                    times[k].append(1000.0 * (time.perf_counter() - started))
            new_ms, old_ms = (statistics.median(t) for t in times)
            print(f"| {entry['name']} | {new_ms:.1f} | {old_ms:.1f} | {new_ms / old_ms:.2f} | "
                  f"{float(np.abs(outputs[0] - outputs[1]).max()):.1e} |", flush=True)


if __name__ == "__main__":
    main()
