"""What 8-bit quantization would buy the shipped U-Net models on the CPU: ms per network call and the output it changes.

    python benchmarks/bench_int8.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--size 512] [--frames 12]
                                    [--variants S,M] [--repeats 7] [--convolutions-only]

For each shipped U-Net model (XS is a filter, not a graph onnxruntime runs) the frames of an orbit
(2° per frame, the volume filling the view) go through ``Pipeline`` with the float32 model; the
network inputs of every call are kept. The model is then quantized statically by onnxruntime
(:func:`~volsr_core.runtime.quantize.quantize_int8`, as ``training/quantize_model.py`` ships them, but
calibrated on the first half of those inputs; every operator quantized, or with ``--convolutions-only`` the
convolutions alone), and both graphs run on the second half, 2 threads,
interleaved: median ms per call of each, their ratio, and the PSNR of the int8 output against the float32 one (how
much of the picture quantization changes; not against a ground truth). Nothing is shipped from here.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort

from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.runtime.models import model_file, shipped_models
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.runtime.quantize import FeedRecorder, quantize_int8
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.sr.metrics import psnr_ssim

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "volumes"


def session(path: Path) -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 2
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--volume", default="CT_AVM.nii.gz:CT-AAA:0,446")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--variants", default="S,M")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--convolutions-only", action="store_true", help="quantize the convolutions alone")
    args = parser.parse_args()
    spec = args.volume if args.volume.startswith("phantom") or Path(args.volume.split(":")[0]).exists() \
        else str(DATA / args.volume)
    scene = load_bench_volume(spec)
    wanted = args.variants.split(",")
    print(f"{scene.label}, {args.size}², {args.frames} frames of 2°; int8 calibrated on the first half"
          + (", the convolutions alone" if args.convolutions_only else "") + "\n")
    print("| model | float32 ms | int8 ms | int8 / float32 | PSNR int8 vs float32 dB |")
    print("|---|---:|---:|---:|---:|")
    for entry in shipped_models():
        if entry["variant"] not in wanted:
            continue
        path = model_file(entry["variant"], entry["scale"])  # the float32 file, whatever runs on the CPU
        pipeline = Pipeline(scene.volume, scene.transfer_function, path, scale=entry["scale"],
                            size=(args.size, args.size), threads=2)
        recorder = pipeline.upscaler.engine = FeedRecorder(pipeline.engine)
        for camera in orbit_around(pipeline.caster.visible_bounds(), args.frames, 2.0):
            pipeline.render(camera)
        half = len(recorder.feeds) // 2
        with tempfile.TemporaryDirectory() as folder:
            quantized = quantize_int8(path, Path(folder) / "int8.onnx", recorder.feeds[:half],
                                      ("Conv",) if args.convolutions_only else None)
            sessions = {"float32": session(path), "int8": session(quantized)}
            times: dict[str, list[float]] = {name: [] for name in sessions}
            scores = []
            for feed in recorder.feeds[half:]:
                outputs = {}
                for _ in range(max(1, args.repeats // 3)):
                    for name, s in sessions.items():
                        started = time.perf_counter()
                        outputs[name] = s.run(None, feed)[0]
                        times[name].append(1000.0 * (time.perf_counter() - started))
                reference = np.clip(outputs["float32"][0].transpose(1, 2, 0), 0, 1)
                scores.append(psnr_ssim(np.clip(outputs["int8"][0].transpose(1, 2, 0), 0, 1), reference,
                                        channel_axis=-1)[0])
        fp32, int8 = statistics.median(times["float32"]), statistics.median(times["int8"])
        print(f"| {entry['name']} | {fp32:.1f} | {int8:.1f} | {int8 / fp32:.2f} | {statistics.fmean(scores):.1f} |",
              flush=True)


if __name__ == "__main__":
    main()
