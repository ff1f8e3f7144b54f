"""ONNX export of a :class:`~volsr_core.sr.network.SuperResolutionNet`, dynamic in batch, height and width.

The graph's inputs are the network's: ``lr`` (B, N+1, C, h, w), ``motion`` (B, N+1, 2, h, w),
``jitter`` (B, N+1, 2) and, for networks that take one, ``history`` (B, history_channels, H, W); its output ``hr``
(B, 3, H, W), H = h * scale. The network's configuration rides in the model's metadata
(``volsr.network``, JSON) so a session knows the scale, frames and features without PyTorch; a
network with a base filter also carries its weights (``volsr.base_filter``), which variant XS runs
in a numba kernel on the CPU (:mod:`volsr_core.runtime.base_filter`).

The graph comes from PyTorch's current exporter (``torch.onnx.export(dynamo=True)``: torch.export, then
onnxscript), not the TorchScript one that PyTorch deprecated. Its graphs keep batch, height and width dynamic
and run in onnxruntime as fast as the old ones, within 1e-6 of PyTorch (tests/test_runtime.py); it needs
``onnxscript`` (the ``onnx`` extra) and opset 18, and takes a few seconds longer per model.
"""
from __future__ import annotations

import json
import logging
import os
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import torch

from volsr_core.atomic import atomic_write
from volsr_core.errors import require_extra
from volsr_core.runtime.base_filter import FILTER_KEY, filter_metadata
from volsr_core.runtime.engines import METADATA_KEY
from volsr_core.sr.network import NetworkConfig, SuperResolutionNet

OPSET = 18  # the lowest opset the torch.export-based exporter writes
EXPORT_BATCH = 2  # torch.export fixes any dimension whose example size is 1: the example batch must not be


def input_names(config: NetworkConfig) -> list[str]:
    """The graph's input names, in call order."""
    return ["lr", "motion", "jitter"] + (["history"] if config.takes_history else [])


def example_inputs(config: NetworkConfig, height: int, width: int, batch: int = 1) -> tuple[torch.Tensor, ...]:
    """Random inputs for an LR frame of ``height`` x ``width`` pixels, in :func:`input_names` order."""
    g = torch.Generator().manual_seed(0)
    frames = config.previous_frames + 1
    inputs = (torch.rand(batch, frames, config.in_channels, height, width, generator=g),
              torch.randn(batch, frames, 2, height, width, generator=g),
              torch.rand(batch, frames, 2, generator=g) - 0.5)
    if config.takes_history:
        inputs += (torch.rand(batch, config.history_channels, height * config.scale, width * config.scale,
                              generator=g),)
    return inputs


def dynamic_shapes(config: NetworkConfig) -> dict[str, dict[int, torch.export.Dim]]:
    """The dynamic axes of every input, by name: batch, LR height and width, and the history's HR size."""
    batch, height, width = torch.export.Dim("batch"), torch.export.Dim("height"), torch.export.Dim("width")
    lr_axes = {0: batch, 3: height, 4: width}
    shapes = {"lr": lr_axes, "motion": lr_axes, "jitter": {0: batch}}
    if config.takes_history:
        shapes["history"] = {0: batch, 2: torch.export.Dim("out_height"), 3: torch.export.Dim("out_width")}
    return shapes


@contextmanager
def quiet_exporter() -> Iterator[None]:
    """Silence, on purpose, the exporter's messages that say nothing about the model exported: PyTorch's own
    deprecation notice raised inside torch.export (``LeafSpec``), the note that an axis name shared by several
    inputs is used once, and the log lines about torchvision operators it cannot register."""
    registry = logging.getLogger("torch.onnx._internal.exporter._registration")
    level = registry.level
    registry.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r".*isinstance\(treespec, LeafSpec\)", category=FutureWarning)
            warnings.filterwarnings("ignore", message=r"# The axis name: .* will not be used", category=UserWarning)
            yield
    finally:
        registry.setLevel(level)


def export_onnx(model: SuperResolutionNet, path: str | os.PathLike, example_size: tuple[int, int] = (24, 32)) -> Path:
    """Write ``model`` as ONNX (opset 18) to ``path``, atomically; returns the path."""
    require_extra("onnxscript", "exporting a model to ONNX")
    config = model.config
    with torch.no_grad(), quiet_exporter():
        program = torch.onnx.export(model.eval(), example_inputs(config, *example_size, batch=EXPORT_BATCH),
                                    input_names=input_names(config), output_names=["hr"],
                                    dynamic_shapes=dynamic_shapes(config), opset_version=OPSET, dynamo=True,
                                    verbose=False)
    graph = program.model_proto
    entry = graph.metadata_props.add()
    entry.key, entry.value = METADATA_KEY, json.dumps(config.to_dict())
    if model.base_filter is not None:  # its weights again, for the CPU kernel (runtime/base_filter.py)
        entry = graph.metadata_props.add()
        entry.key, entry.value = FILTER_KEY, filter_metadata(*(w.numpy() for w in model.base_filter.weights()))
    graph.producer_name = "volsr"
    with atomic_write(path) as fh:
        fh.write(graph.SerializeToString())
    return Path(path)
