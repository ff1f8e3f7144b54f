"""Inference engines with one call signature: onnxruntime (TensorRT / CUDA / CPU) and PyTorch.

``engine(lr, motion, jitter, history=None) -> (B, 3, H, W)`` float32 numpy, inputs as the
network takes them (numpy, float32; see :mod:`volsr_core.sr.network`). ``engine.config`` is the
network's :class:`NetworkConfig`. The PyTorch engine is for training and debugging; the
onnxruntime one is what hosts and the CLI use.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from volsr_core.errors import InputError, require_extra
from volsr_core.runtime.base_filter import FILTER_KEY, Scratch, filter_image, read_filter_metadata
from volsr_core.sr.history import stand_in_history

METADATA_KEY = "volsr.network"  # the ONNX metadata entry holding the NetworkConfig as JSON
PROVIDER_ORDER = ("TensorrtExecutionProvider", "CUDAExecutionProvider", "CPUExecutionProvider")


def choose_providers(available: Sequence[str] | None = None) -> list[str]:
    """The execution providers to use, best first: TensorRT, CUDA, CPU, those present."""
    if available is None:
        require_extra("onnxruntime", "running an ONNX model")
        import onnxruntime as ort

        available = ort.get_available_providers()
    return [p for p in PROVIDER_ORDER if p in available] or ["CPUExecutionProvider"]


def _network_config(text: str, path: Path):
    """The NetworkConfig in the ONNX metadata entry ``text`` (JSON) of the model at ``path``."""
    from volsr_core.sr.network_config import NetworkConfig

    try:
        mapping = json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(path, f"{METADATA_KEY}: not valid JSON ({err})") from None
    return NetworkConfig.from_dict(mapping, source=path, key=METADATA_KEY)


class OnnxEngine:
    """An onnxruntime session over a VolSR ONNX file (:func:`~volsr_core.runtime.export.export_onnx`).

    ``providers`` defaults to :func:`choose_providers`; ``fp16`` converts the graph to float16
    (inputs and outputs stay float32) when a GPU provider runs it, and is ignored on the CPU;
    ``threads`` sets onnxruntime's intra-op threads (default: its own choice). A network that is
    only its base filter (variant XS) runs in the upscaler's own kernels instead of the session, with
    the weights from the file's metadata in ``base_filter``, whichever providers are given: on the CPU
    :func:`~volsr_core.runtime.base_filter.filter_image` (the same sums, a few times faster), on a GPU
    the CUDA kernels next to the frame (``StatefulUpscaler(..., device="cuda")``): a round trip through
    a provider costs more than the filter (docs/performance-gpu.md); None for every other network.
    """

    def __init__(self, path: str | os.PathLike, providers: Sequence[str] | None = None, fp16: bool = False,
                 threads: int | None = None):
        require_extra("onnxruntime", f"{path}: running an ONNX model")
        import onnxruntime as ort

        self.path = Path(path)
        self.providers = list(providers) if providers else choose_providers()
        options = ort.SessionOptions()
        if threads:
            options.intra_op_num_threads = int(threads)
        # no busy-waiting between runs: spinning intra-op threads take the cores from the ray caster and TAAU
        # that run next (on 2 cores a TAAU call after a network run took 22 ms instead of 10)
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        try:
            model: Any = self.path.read_bytes()
        except OSError as err:
            raise InputError(self.path, f"cannot read the model ({err.strerror})") from None
        self.fp16 = bool(fp16) and self.providers[0] != "CPUExecutionProvider"
        if self.fp16:
            import onnx
            from onnxruntime.transformers.float16 import convert_float_to_float16

            model = convert_float_to_float16(onnx.load_from_string(model), keep_io_types=True).SerializeToString()
        try:
            self.session = ort.InferenceSession(model, options, providers=self.providers)
        except Exception as err:  # onnxruntime raises its own exception types for damaged files
            raise InputError(self.path, f"not a loadable ONNX model ({' '.join(str(err).split())[:160]})") from None
        meta = self.session.get_modelmeta().custom_metadata_map
        if METADATA_KEY not in meta:
            raise InputError(self.path, f"an ONNX model without VolSR metadata ('{METADATA_KEY}')")
        self.config = _network_config(meta[METADATA_KEY], self.path)
        self.input_names = [i.name for i in self.session.get_inputs()]
        self.base_filter = None  # (weights (n, 3, k, k), bias (n, 3)) when the CPU kernel runs the network
        self._scratch = Scratch()  # the kernel's work buffers, kept between calls
        if not self.config.widths and FILTER_KEY in meta:
            self.base_filter = read_filter_metadata(meta[FILTER_KEY], self.path, self.config.base_kernel,
                                                    self.config.base_orientations)

    def __call__(self, lr: np.ndarray, motion: np.ndarray, jitter: np.ndarray,
                 history: np.ndarray | None = None) -> np.ndarray:
        values = {"lr": lr, "motion": motion, "jitter": jitter}
        if self.config.takes_history:
            values["history"] = stand_in_history(lr, self.config.scale) if history is None else history
        if self.base_filter is not None:
            base = values["history"] if self.config.taau_base else stand_in_history(lr, self.config.scale)
            return np.stack([filter_image(image[:3].transpose(1, 2, 0), *self.base_filter, scratch=self._scratch)
                             .transpose(2, 0, 1)
                             for image in base])
        # the exporter drops inputs a configuration never reads (motion when N = 0 without recurrence)
        feed = {name: np.ascontiguousarray(values[name], dtype=np.float32) for name in self.input_names}
        return self.session.run(None, feed)[0]


class TorchEngine:
    """The PyTorch network behind the same call: numpy in, numpy out, no gradients. A network that is only its base
    filter (variant XS) also hands its weights over as ``base_filter``, as :class:`OnnxEngine` does, so that the
    upscaler runs it in its own kernels, the CPU's or, on "cuda", the CUDA ones next to the frame (on a lent H200 the
    round trip through torch cost 17.6-19.6 ms a frame at 1024² beyond TAAU 2x: docs/performance-gpu.md); None for
    every other network."""

    def __init__(self, model, device: str = "cpu"):
        require_extra("torch", "running a PyTorch model")
        import torch

        self.torch = torch
        self.device = torch.device(device)
        self.model = model.to(self.device).eval()
        self.config = model.config
        self.providers = [f"torch:{self.device}"]
        self.base_filter = None  # (weights (n, 3, k, k), bias (n, 3)) for the CPU kernel
        if not self.config.widths and getattr(model, "base_filter", None) is not None:
            self.base_filter = tuple(np.ascontiguousarray(t.float().cpu().numpy()) for t in model.base_filter.weights())

    def __call__(self, lr: np.ndarray, motion: np.ndarray, jitter: np.ndarray,
                 history: np.ndarray | None = None) -> np.ndarray:
        torch = self.torch
        args = [torch.from_numpy(np.ascontiguousarray(v, dtype=np.float32)).to(self.device)
                for v in (lr, motion, jitter)]
        if self.config.takes_history and history is not None:
            args.append(torch.from_numpy(np.ascontiguousarray(history, dtype=np.float32)).to(self.device))
        with torch.no_grad():
            return self.model(*args).float().cpu().numpy()


def open_engine(model: str | os.PathLike | Any, backend: str = "auto", device: str = "cpu", fp16: bool = False,
                threads: int | None = None):
    """An engine for a .onnx file (onnxruntime), a .pt model file or an ``nn.Module`` (PyTorch).

    ``backend="auto"`` follows the file type; ``"torch"`` with an ``.onnx`` path is an error.
    """
    if not isinstance(model, (str, os.PathLike)):
        return TorchEngine(model, device)
    path = Path(model)
    if path.suffix == ".onnx" and backend in ("auto", "onnxruntime"):
        providers = None if device != "cpu" else ["CPUExecutionProvider"]
        return OnnxEngine(path, providers=providers, fp16=fp16, threads=threads)
    if path.suffix == ".onnx":
        raise InputError(path, "an ONNX model runs in onnxruntime; give the .pt file for --backend torch")
    require_extra("torch", f"{path}: a PyTorch model file")
    from volsr_core.sr.checkpoint import load_model

    return TorchEngine(load_model(path), device)
