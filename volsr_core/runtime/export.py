"""ONNX export of a :class:`~volsr_core.sr.network.SuperResolutionNet`, dynamic in batch, height and width.

The graph's inputs are the network's: ``lr`` (B, N+1, C, h, w), ``motion`` (B, N+1, 2, h, w),
``jitter`` (B, N+1, 2) and, for networks that take one, ``history`` (B, history_channels, H, W); its output ``hr``
(B, 3, H, W), H = h * scale. The network's configuration rides in the model's metadata
(``volsr.network``, JSON) so a session knows the scale, frames and features without PyTorch.
"""
from __future__ import annotations

import io
import json
import os
from pathlib import Path

import torch

from volsr_core.atomic import atomic_write
from volsr_core.runtime.engines import METADATA_KEY
from volsr_core.sr.network import NetworkConfig, SuperResolutionNet

OPSET = 17


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
        inputs += (torch.rand(batch, config.history_channels, height * config.scale, width * config.scale, generator=g),)
    return inputs


def export_onnx(model: SuperResolutionNet, path: str | os.PathLike, example_size: tuple[int, int] = (24, 32)) -> Path:
    """Write ``model`` as ONNX (opset 17) to ``path``, atomically; returns the path."""
    import onnx

    config = model.config
    names = input_names(config)
    lr_axes = {0: "batch", 3: "height", 4: "width"}
    dynamic = {"lr": lr_axes, "motion": lr_axes, "jitter": {0: "batch"},
               "history": {0: "batch", 2: "out_height", 3: "out_width"},
               "hr": {0: "batch", 2: "out_height", 3: "out_width"}}
    buffer = io.BytesIO()
    with torch.no_grad():
        torch.onnx.export(model.eval(), example_inputs(config, *example_size), buffer, input_names=names,
                          output_names=["hr"], dynamic_axes={k: v for k, v in dynamic.items() if k in names + ["hr"]},
                          opset_version=OPSET, dynamo=False)
    graph = onnx.load_from_string(buffer.getvalue())
    entry = graph.metadata_props.add()
    entry.key, entry.value = METADATA_KEY, json.dumps(config.to_dict())
    graph.producer_name = "volsr"
    with atomic_write(path) as fh:
        fh.write(graph.SerializeToString())
    return Path(path)
