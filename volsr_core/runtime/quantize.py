"""8-bit copies of the U-Nets' ONNX graphs, for onnxruntime on the CPU.

onnxruntime's static quantization (QDQ: int8 weights per output channel, uint8 activations, their ranges from
calibration inputs) runs the U-Nets' convolutions in integer kernels: inside ``volsr bench`` on the 2-core machine,
side by side with the float32 files at 512², 2°, the shipped U-Nets' steps after the render were 1.3-20 ms shorter
for 0.002-0.18 dB of PSNR (at 1024² S 2x's, every operator quantized, lost up to 0.50 dB; docs/performance.md,
"8-bit U-Nets on the CPU"). The
clipped history input and every node that reads it stay in float32 (:func:`history_nodes`): the base the residual
is added to keeps its precision. A GPU provider runs the float32
file (or its fp16 conversion, ``OnnxEngine(fp16=True)``).

Needs ``onnx`` and onnxruntime's quantization tools, a shipping step (``training/quantize_model.py``); running the
file needs onnxruntime alone.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from volsr_core.atomic import atomic_write
from volsr_core.errors import require_extra

class FeedRecorder:
    """An engine's stand-in for the upscaler (``StatefulUpscaler.engine``) that runs ``engine`` and keeps the feed of
    every call, the graph's inputs by name as onnxruntime takes them: calibration inputs, as the runtime feeds it."""

    def __init__(self, engine):
        self.engine, self.config = engine, engine.config
        self.feeds: list[dict[str, np.ndarray]] = []

    def __call__(self, lr: np.ndarray, motion: np.ndarray, jitter: np.ndarray,
                 history: np.ndarray | None = None) -> np.ndarray:
        values = {"lr": lr, "motion": motion, "jitter": jitter, "history": history}
        self.feeds.append({name: np.ascontiguousarray(values[name], dtype=np.float32)
                           for name in self.engine.input_names})
        return self.engine(lr, motion, jitter, history)


def history_nodes(graph) -> list[str]:
    """The names of the Clip on ``graph``'s (an ``onnx.GraphProto``) history input and of every node that reads its
    output. Left in float32: quantized, onnxruntime 1.31's optimizer loses the input's shape when it fuses the
    convolutions on it (QLinearConv: "Input tensor must have at least 3 dimensions"), and one quantized reader (the
    last Add, base + residual) would quantize the clipped history for them all."""
    clips = [node for node in graph.node if node.op_type == "Clip" and node.input[0] == "history"]
    clipped = {node.output[0] for node in clips}
    return [node.name for node in clips] + [node.name for node in graph.node if set(node.input) & clipped]


def quantize_int8(source: str | os.PathLike, target: str | os.PathLike, feeds: Iterable[dict[str, np.ndarray]],
                  op_types: Sequence[str] | None = None) -> Path:
    """Write the 8-bit copy of the ONNX model ``source`` to ``target`` (atomically), its activation ranges
    calibrated on ``feeds`` (dicts of the graph's input names to float32 arrays, as the runtime feeds it: the
    upscaler's calls on rendered frames); the model's metadata (its ``volsr.network`` config) is kept. ``op_types``:
    the operators quantized (None: every one onnxruntime can; ("Conv",): the convolutions alone, the rest float32)."""
    require_extra("onnx", "quantizing a model")
    import onnx
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    class Feeds(CalibrationDataReader):
        def __init__(self) -> None:
            self.remaining = iter(feeds)

        def get_next(self) -> dict[str, np.ndarray] | None:
            return next(self.remaining, None)

    target = Path(target)
    with tempfile.TemporaryDirectory() as folder:
        prepared, quantized = Path(folder) / "prepared.onnx", Path(folder) / "int8.onnx"
        quant_pre_process(str(source), str(prepared), skip_symbolic_shape=True)
        quantize_static(str(prepared), str(quantized), Feeds(), quant_format=QuantFormat.QDQ, per_channel=True,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                        nodes_to_exclude=history_nodes(onnx.load(str(prepared)).graph),
                        **({} if op_types is None else {"op_types_to_quantize": list(op_types)}))
        with atomic_write(target, "wb") as fh:
            fh.write(quantized.read_bytes())
    return target
