"""8-bit copies of the U-Nets: quantized where the float32 graph computes, float32 where it reads the history, and
close to the float32 file's output on the calls they were calibrated on."""
from __future__ import annotations

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from volsr_core.io import make_phantom  # noqa: E402
from volsr_core.runtime.engines import OnnxEngine  # noqa: E402
from volsr_core.runtime.pipeline import Pipeline  # noqa: E402
from volsr_core.runtime.quantize import FeedRecorder, history_nodes, quantize_int8  # noqa: E402
from volsr_core.scene import Volume, get_preset  # noqa: E402
from volsr_core.scene.camera_paths import orbit_around  # noqa: E402


def test_the_8_bit_copy_keeps_the_history_in_float32_and_stays_near_the_float32_output(model, tmp_path):
    """The shipped S 4x quantized on the upscaler's own calls along a phantom orbit: its convolutions read
    dequantized int8 tensors, no QuantizeLinear reads the history input or its clip, the model's config is kept,
    and on those calls its output differs from the float32 file's, by little: PSNR above 30 dB against it."""
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48)))
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), model, scale=4, size=(128, 128), threads=2)
    recorder = pipeline.upscaler.engine = FeedRecorder(pipeline.engine)
    for camera in orbit_around(pipeline.caster.visible_bounds(), 5, 2.0):
        pipeline.render(camera)
    assert len(recorder.feeds) == 5 and set(recorder.feeds[0]) == set(pipeline.engine.input_names)
    target = quantize_int8(model, tmp_path / "int8.onnx", recorder.feeds)
    graph = onnx.load(str(target)).graph
    assert sum(node.op_type == "DequantizeLinear" for node in graph.node) > 10
    kept = set(history_nodes(graph))
    clipped = {o for node in graph.node if node.name in kept and node.op_type == "Clip" for o in node.output}
    assert clipped and not [node for node in graph.node if node.op_type == "QuantizeLinear"
                            and set(node.input) & (clipped | {"history"})]
    engines = [OnnxEngine(path, providers=["CPUExecutionProvider"]) for path in (model, target)]
    assert engines[1].config == engines[0].config
    for feed in recorder.feeds:
        outputs = [np.clip(engine.session.run(None, feed)[0], 0, 1) for engine in engines]
        error = float(np.mean((outputs[1] - outputs[0]) ** 2))
        assert 0.0 < error and 10 * np.log10(1.0 / error) > 30.0
