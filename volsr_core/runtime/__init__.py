"""Inference outside training: ONNX export, engines (onnxruntime / PyTorch), the stateful upscaler,
the shipped models and the Pipeline that hosts and the CLI share. Import the modules directly;
only :mod:`volsr_core.runtime.export` needs torch."""
