"""Pipeline: volume + transfer function + model + scale + output size; a camera in, an upscaled image out.

The one object the CLI, the benchmark and every host use: it renders the LR frame with the next
Halton jitter offset and motion vectors against the previous camera, and upscales it with a
:class:`~volsr_core.runtime.upscaler.StatefulUpscaler`.
"""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from volsr_core.render.raycaster import RayCaster
from volsr_core.runtime.engines import open_engine
from volsr_core.runtime.upscaler import StatefulUpscaler
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.temporal.jitter import halton_jitter, jitter_phases


class Pipeline:
    """Renders ``volume`` at 1/``scale`` of ``size`` and upscales it with ``model``.

    - ``model``: an .onnx or .pt file, an ``nn.Module``, or None for the shipped model of
      ``variant`` at ``scale`` (resources/models, SHA-256 checked);
    - ``size``: output (width, height) in pixels; any size: the LR frame is ceil(size / scale)
      and the output is cropped to ``size``;
    - ``device``: "cpu" or "cuda", for the ray caster and the network;
    - ``backend``: "auto" (by file type), "onnxruntime" or "torch".

    ``render(camera)`` returns float32 (H, W, 3) in [0, 1]; ``last_timings`` holds the ms spent
    rendering and upscaling that frame. Call :meth:`reset` on a camera cut (the upscaler also
    resets by itself on implausible motion and on a new size).
    """

    def __init__(self, volume: Volume, transfer_function: TransferFunction, model: Any = None, *,
                 scale: int = 4, size: tuple[int, int] = (512, 512), variant: str = "S", device: str = "cpu",
                 backend: str = "auto", fp16: bool = False, threads: int | None = None,
                 sample_distance: float | None = None, background: tuple[float, float, float] = (0.0, 0.0, 0.0)):
        if model is None:
            from volsr_core.runtime.models import model_file

            model = model_file(variant, scale, "onnx" if backend != "torch" else "pt")
        self.engine = open_engine(model, backend=backend, device=device, fp16=fp16, threads=threads)
        if self.engine.config.scale != scale:
            raise ValueError(f"the model upscales {self.engine.config.scale}x, not {scale}x")
        self.scale = int(scale)
        self._caster_options = {"sample_distance": sample_distance, "device": device}
        self.caster = RayCaster(volume, transfer_function, background=background, **self._caster_options)
        self.upscaler = StatefulUpscaler(self.engine)
        self.size = (int(size[0]), int(size[1]))
        self.frame = 0
        self.previous_camera: Camera | None = None
        self.last_timings: dict[str, float] = {}
        self.last_low_resolution = None

    @property
    def low_resolution_size(self) -> tuple[int, int]:
        """(width, height) of the rendered LR frame."""
        return math.ceil(self.size[0] / self.scale), math.ceil(self.size[1] / self.scale)

    def resize(self, width: int, height: int) -> None:
        """A new output size; the history starts afresh at the next frame."""
        self.size = (int(width), int(height))

    def set_volume(self, volume: Volume) -> None:
        """A new volume (same transfer function and background); the history is dropped."""
        caster = self.caster
        self.caster = RayCaster(volume, caster.transfer_function, background=caster.background, **self._caster_options)
        self.reset()

    def set_transfer_function(self, transfer_function: TransferFunction) -> None:
        """A new transfer function; the history is dropped (old colours would bleed in)."""
        self.caster.transfer_function = transfer_function
        self.reset()

    def set_background(self, background: tuple[float, float, float]) -> bool:
        """A new background colour (RGB in [0, 1]); the history is dropped if it differs. Returns
        whether it did."""
        background = tuple(float(c) for c in background)
        if background == tuple(self.caster.background):
            return False
        self.caster.background = background
        self.reset()
        return True

    def reset(self) -> None:
        """Forget previous frames (a camera cut): the next frame has no motion vectors or history."""
        self.upscaler.reset()
        self.previous_camera = None

    def render(self, camera: Camera) -> np.ndarray:
        """The upscaled image for ``camera``: float32 (H, W, 3) in [0, 1], H, W = ``size``."""
        w, h = self.low_resolution_size
        jitter = halton_jitter(self.frame, jitter_phases(self.scale))
        started = time.perf_counter()
        lr = self.caster.render(camera, w, h, jitter=jitter, previous_camera=self.previous_camera)
        rendered = time.perf_counter()
        image = self.upscaler.upscale(lr)[: self.size[1], : self.size[0]]
        done = time.perf_counter()
        self.last_timings = {"render_ms": 1000 * (rendered - started), "network_ms": 1000 * (done - rendered),
                             "total_ms": 1000 * (done - started)}
        self.last_low_resolution = lr
        self.previous_camera = camera
        self.frame += 1
        return image

