"""Pipeline: volume + transfer function + model + scale + output size; a camera in, an upscaled image out.

The one object the CLI, the benchmark and every host use: it renders the LR frame with the next
Halton jitter offset and motion vectors against the previous camera, and upscales it with a
:class:`~volsr_core.runtime.upscaler.StatefulUpscaler`. Hosts follow their scene with one call,
:meth:`Pipeline.update`, before each :meth:`Pipeline.render`.
"""
from __future__ import annotations

import json
import math
import time
from typing import Any, Sequence

import numpy as np

from volsr_core.render.device import ready_at, to_host
from volsr_core.render.raycaster import RayCaster
from volsr_core.runtime.engines import open_engine
from volsr_core.runtime.upscaler import StatefulUpscaler
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.temporal.jitter import halton_jitter, jitter_phases


class KeepsLastFrame:
    """``last_frame``, the last LR :class:`~volsr_core.render.features.FeatureFrame` as rendered (on the GPU where
    the frame stayed there; None when there is none), and ``last_low_resolution``, the same in host memory: copied
    back when read, not every frame."""

    last_frame = None

    @property
    def last_low_resolution(self):
        return None if self.last_frame is None else self.last_frame.to_host()


class Pipeline(KeepsLastFrame):
    """Renders ``volume`` at 1/``scale`` of ``size`` and upscales it with ``model``.

    - ``model``: an .onnx or .pt file, an ``nn.Module``, or None for the shipped model of
      ``variant`` at ``scale`` (resources/models, SHA-256 checked);
    - ``scale``: the upscaling factor; None: the model's own, or for a shipped model
      :data:`~volsr_core.runtime.models.DEFAULT_SCALE` (2); a model of another scale is an error;
    - ``variant``: None: :func:`~volsr_core.runtime.models.default_variant`, the fastest shipped at
      ``scale`` (XS at 2x: the model that pays off on a CPU, docs/performance.md);
    - ``size``: output (width, height) in pixels; any size: the LR frame is ceil(size / scale)
      and the output is cropped to ``size``;
    - ``device``: "cpu" or "cuda", for the ray caster and the network; on "cuda" a base-filter model on TAAU
      (variant XS) keeps the frame on the GPU (render, TAAU and filter there, one RGB image copied back);
    - ``backend``: "auto" (by file type), "onnxruntime" or "torch";
    - ``max_turn`` (degrees), ``max_zoom``: a camera that turned or zoomed further than this since
      the last frame is a cut (:func:`~volsr_core.runtime.upscaler.camera_jump`);
    - ``slabs``: K > 0 renders each frame in K depth slabs and accumulates them with the layered TAAU, one
      history per slab (docs/temporal.md, "Layered history"); only for a base-filter model on TAAU (XS);
      0 runs the TAAU on the frame's colour; None (the default) the model's own
      (:func:`~volsr_core.runtime.upscaler.default_slabs`: two for XS at 4x and more, else 0).

    ``render(camera)`` returns float32 (H, W, 3) in [0, 1]; ``last_timings`` holds the ms spent
    rendering and upscaling that frame (``render_ms``, ``network_ms``, ``total_ms``: on the GPU until its work
    is done) and copying the image from the GPU (``readback_ms``, 0 on the host), ``last_frame`` the LR frame
    as rendered and ``last_low_resolution`` the same in host memory. :meth:`update` follows a changed volume,
    transfer function, background or size; :meth:`reset` drops the history for the caller's own reasons (the upscaler
    also drops it by itself on camera jumps, implausible motion and a new size). ``resets`` counts
    the drops, ``last_reset_reason`` says why the last one happened.
    """

    def __init__(self, volume: Volume, transfer_function: TransferFunction, model: Any = None, *,
                 scale: int | None = None, size: tuple[int, int] = (512, 512), variant: str | None = None,
                 device: str = "cpu",
                 backend: str = "auto", fp16: bool = False, threads: int | None = None,
                 sample_distance: float | None = None, background: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 max_turn: float = 30.0, max_zoom: float = 2.0, slabs: int | None = None):
        if model is None:
            from volsr_core.runtime.models import DEFAULT_SCALE, default_variant, model_file

            scale = DEFAULT_SCALE if scale is None else scale
            model = model_file(variant or default_variant(scale), scale, "onnx" if backend != "torch" else "pt")
        self.engine = open_engine(model, backend=backend, device=device, fp16=fp16, threads=threads)
        if scale is not None and self.engine.config.scale != scale:
            raise ValueError(f"the model upscales {self.engine.config.scale}x, not {scale}x")
        self.scale = int(self.engine.config.scale)
        # ray starts jittered per pixel and frame (seeded by the frame number): the temporal history averages
        # the offsets instead of keeping a fixed start's rings
        self._caster_options = {"sample_distance": sample_distance, "device": device, "start_jitter": "ign"}
        self.caster = RayCaster(volume, transfer_function, background=tuple(float(c) for c in background),
                                **self._caster_options)
        self.upscaler = StatefulUpscaler(self.engine, max_turn=max_turn, max_zoom=max_zoom, slabs=slabs, device=device)
        self.slabs = self.upscaler.slabs
        self.size = (int(size[0]), int(size[1]))
        self._tf_key = _tf_key(transfer_function)
        self.frame = 0
        self.previous_camera: Camera | None = None
        self.last_timings: dict[str, float] = {}

    @property
    def low_resolution_size(self) -> tuple[int, int]:
        """(width, height) of the rendered LR frame."""
        return math.ceil(self.size[0] / self.scale), math.ceil(self.size[1] / self.scale)

    @property
    def resets(self) -> int:
        """How many times the history was dropped."""
        return self.upscaler.resets

    @property
    def last_reset_reason(self) -> str:
        return self.upscaler.last_reset_reason

    def update(self, *, volume: Volume | None = None, transfer_function: TransferFunction | None = None,
               background: Sequence[float] | None = None, size: Sequence[int] | None = None) -> str | None:
        """Follow the host: take each setting given that differs from the current one, then drop the
        history once if any did. Returns why ("new volume", "new transfer function", "new background",
        "new size", joined by ", ") or None when nothing changed; calling it again with the same
        settings changes nothing. A volume is new when it is another object; a transfer function when
        its definition differs; a background is RGB in [0, 1]; a size is (width, height) in pixels."""
        changes = []
        if volume is not None and volume is not self.caster.volume:
            self.caster = RayCaster(volume, self.caster.transfer_function, background=self.caster.background,
                                    **self._caster_options)
            changes.append("new volume")
        if transfer_function is not None and _tf_key(transfer_function) != self._tf_key:
            self.caster.transfer_function = transfer_function
            self._tf_key = _tf_key(transfer_function)
            changes.append("new transfer function")
        if background is not None and tuple(float(c) for c in background) != tuple(self.caster.background):
            self.caster.background = tuple(float(c) for c in background)
            changes.append("new background")
        if size is not None and (int(size[0]), int(size[1])) != self.size:
            self.size = (int(size[0]), int(size[1]))
            changes.append("new size")
        if not changes:
            return None
        reason = ", ".join(changes)
        self.reset(reason)
        return reason

    def reset(self, reason: str = "asked") -> None:
        """Forget previous frames (a camera cut): the next frame has no motion vectors or history."""
        self.upscaler.reset(reason)
        self.previous_camera = None

    def render(self, camera: Camera) -> np.ndarray:
        """The upscaled image for ``camera``: float32 (H, W, 3) in [0, 1], H, W = ``size``."""
        w, h = self.low_resolution_size
        jitter = halton_jitter(self.frame, jitter_phases(self.scale))
        started = time.perf_counter()
        lr = self.caster.render(camera, w, h, jitter=jitter, previous_camera=self.previous_camera, seed=self.frame,
                                slabs=self.slabs, on_device=self.upscaler.on_device)
        rendered = time.perf_counter()
        image = self.upscaler.upscale(lr, self.caster.background)
        done = ready_at(image)
        image, readback_ms = to_host(image)
        self.last_timings = {"render_ms": 1000 * (rendered - started), "network_ms": 1000 * (done - rendered),
                             "total_ms": 1000 * (done - started), "readback_ms": readback_ms}
        self.last_frame = lr
        self.previous_camera = camera
        self.frame += 1
        return image[: self.size[1], : self.size[0]]


def _tf_key(tf: TransferFunction) -> str:
    """A transfer function's definition as text: equal texts, equal functions."""
    return json.dumps(tf.to_dict(), sort_keys=True)
