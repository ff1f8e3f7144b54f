"""What 8-bit quantization would buy the shipped U-Net models on the CPU: ms per network call and the output it changes.

    python benchmarks/bench_int8.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--size 512] [--frames 12]
                                    [--variants S,M] [--repeats 7]

For each shipped U-Net model (XS is a filter, not a graph onnxruntime runs) the frames of an orbit
(2° per frame, the volume filling the view) go through ``Pipeline`` with the float32 model; the
network inputs of every call are kept. The model is then quantized statically by onnxruntime
(``quantize_static``: QDQ, int8 weights per channel, uint8 activations, calibrated on the first half
of those inputs), and both graphs run on the second half, 2 threads, interleaved: median ms per call
of each, their ratio, and the PSNR of the int8 output against the float32 one (how much of the
picture quantization changes; not against a ground truth). The clipped history input and what reads it stay in float32
(:func:`history_nodes`). Nothing is shipped from here.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
from onnxruntime.quantization.shape_inference import quant_pre_process

from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.runtime.models import model_file, shipped_models
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.sr.metrics import psnr_ssim

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "volumes"


class Recorder:
    """An engine stand-in that keeps the inputs of every call (as the ONNX graph's feed) and runs the engine."""

    def __init__(self, engine):
        self.engine, self.config, self.feeds = engine, engine.config, []

    def __call__(self, lr, motion, jitter, history=None):
        values = {"lr": lr, "motion": motion, "jitter": jitter, "history": history}
        self.feeds.append({name: np.ascontiguousarray(values[name], dtype=np.float32)
                           for name in self.engine.input_names})
        return self.engine(lr, motion, jitter, history)


class Feeds(CalibrationDataReader):
    def __init__(self, feeds: list[dict]):
        self.remaining = iter(feeds)

    def get_next(self):
        return next(self.remaining, None)


def history_nodes(path: Path) -> list[str]:
    """The Clip on the history input and every node that reads its output, left in float32: quantized, onnxruntime
    1.31's optimizer loses the input's shape when it fuses the convolutions on it (QLinearConv: "Input tensor must
    have at least 3 dimensions"), and a quantized reader (the U-Nets' last Add, base + residual, since the blocks of
    16) quantizes the clipped history for them all."""
    graph = onnx.load(str(path)).graph
    clips = [node for node in graph.node if node.op_type == "Clip" and node.input[0] == "history"]
    clipped = {node.output[0] for node in clips}
    return [node.name for node in clips] + [node.name for node in graph.node if set(node.input) & clipped]


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
    args = parser.parse_args()
    spec = args.volume if args.volume.startswith("phantom") or Path(args.volume.split(":")[0]).exists() \
        else str(DATA / args.volume)
    scene = load_bench_volume(spec)
    wanted = args.variants.split(",")
    print(f"{scene.label}, {args.size}², {args.frames} frames of 2°; int8 calibrated on the first half\n")
    print("| model | float32 ms | int8 ms | int8 / float32 | PSNR int8 vs float32 dB |")
    print("|---|---:|---:|---:|---:|")
    for entry in shipped_models():
        if entry["variant"] not in wanted:
            continue
        path = model_file(entry["variant"], entry["scale"])
        pipeline = Pipeline(scene.volume, scene.transfer_function, path, scale=entry["scale"],
                            size=(args.size, args.size), threads=2)
        recorder = pipeline.upscaler.engine = Recorder(pipeline.engine)
        for camera in orbit_around(pipeline.caster.visible_bounds(), args.frames, 2.0):
            pipeline.render(camera)
        half = len(recorder.feeds) // 2
        with tempfile.TemporaryDirectory() as folder:
            prepared, quantized = Path(folder) / "prepared.onnx", Path(folder) / "int8.onnx"
            quant_pre_process(str(path), str(prepared), skip_symbolic_shape=True)
            quantize_static(str(prepared), str(quantized), Feeds(recorder.feeds[:half]), quant_format=QuantFormat.QDQ,
                            per_channel=True, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                            nodes_to_exclude=history_nodes(prepared))
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
