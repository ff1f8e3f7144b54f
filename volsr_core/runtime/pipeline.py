"""Pipeline: volume + transfer function + model + scale + output size; a camera in, an upscaled image out.

The one object the CLI, the benchmark and every host use: it renders the LR frame with the next
Halton jitter offset and motion vectors against the previous camera, and upscales it with a
:class:`~volsr_core.runtime.upscaler.StatefulUpscaler`. Hosts follow their scene with one call,
:meth:`Pipeline.update`, before each :meth:`Pipeline.render`.
"""
from __future__ import annotations

import dataclasses
import json
import math
import statistics
import time
from collections import deque
from typing import Any, Sequence

import numpy as np

from volsr_core.render.device import placed_like, ready_at, to_host
from volsr_core.render.raycaster import RayCaster
from volsr_core.render.slabs import composited, mixed_share
from volsr_core.runtime.engines import open_engine
from volsr_core.runtime.upscaler import StatefulUpscaler
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.sr.network_config import VARIANTS
from volsr_core.temporal.jitter import halton_jitter, jitter_phases
from volsr_core.temporal.taau import view_rotation

STRETCH_FROM = 2.0  # stretch "auto": by 2 where a voxel spans at least this many output pixels (docs/performance.md)
# stretch "auto" below STRETCH_FROM: by 2 while the view turns fast, from 3.5 degrees a frame times the view's output
# pixels per voxel (from about 2.3° at 512² on the bench's volumes, 4.7° at 256²), back below 2.5 (docs/performance.md)
FAST_TURN = (2.5, 3.5)
TURN_FRAMES = 3  # ... taken as the median of the last this many frames
# depth slabs by look (``slabs`` None, a base-filter model on slabs): the model's two slabs where at least this share
# of a new history's first frame's shown pixels mix two slabs (render.slabs.mixed_share), else one
# (docs/performance.md, "Depth slabs by look"): where the front hides what lies behind it, or nothing lies behind it,
# two slabs cost more render time than they keep apart
MIXED_SHARE = 0.03


class KeepsLastFrame:
    """``last_frame``, the last LR :class:`~volsr_core.render.features.FeatureFrame` as rendered (on the GPU where
    the frame stayed there; None when there is none), and ``last_low_resolution``, the same in host memory: copied
    back when read, not every frame."""

    last_frame = None

    @property
    def last_low_resolution(self):
        return None if self.last_frame is None else self.last_frame.to_host()


class Pipeline(KeepsLastFrame):
    """Renders ``volume`` at 1/``scale`` of ``size`` and upscales it with ``model`` (and a bicubic ``stretch``).

    - ``model``: an .onnx or .pt file, an ``nn.Module``, or None for the shipped model of
      ``variant`` at ``scale`` / ``stretch`` (resources/models, SHA-256 checked; on the CPU its 8-bit ONNX file where
      one ships, :func:`~volsr_core.runtime.models.model_file_to_run`);
    - ``scale``: the upscaling factor from the rendered frame to ``size``; None: the model's own times
      ``stretch``, or for a shipped model :data:`~volsr_core.runtime.models.DEFAULT_SCALE` (2) times ``stretch``;
      a model of a scale other than ``scale`` / ``stretch`` is an error;
    - ``stretch``: 1 (the default), or k > 1: the model makes 1/k of ``size`` and its image is stretched by k to
      ``size`` by the upscaler (the same view, as VTK stretches a reduced rendering; Keys' cubic with
      :data:`~volsr_core.runtime.upscaler.STRETCH_CUBIC_A`, clamped to [0, 1]: sharper than bilinear, for about its
      time), so that its history and filter work on k² times fewer pixels: where a voxel spans several output pixels,
      detail the frames' samples do not hold anyway (docs/performance.md, "Where the history lives"); "auto": at an
      even ``scale`` of 4 or more with a shipped model (``model`` None) at half of it, 2 where the view's voxels span
      at least :data:`STRETCH_FROM` output pixels (``RayCaster.pixels_per_voxel`` at ``size``, judged at each new
      history: the first frame, a :meth:`reset` or :meth:`update` that changed something, a turn beyond
      ``max_turn``) or while the view turns fast: from :data:`FAST_TURN` [1] degrees a frame times the view's output
      pixels per voxel (the median over the last :data:`TURN_FRAMES` frames of
      :func:`~volsr_core.temporal.taau.view_rotation` times it: about how far the volume moves in pixels) until that
      falls below :data:`FAST_TURN` [0], where the full-size model's history goes stale sooner than the stretched
      one's (docs/performance.md, "How fast the view turns"); else 1; both models opened up front, each change of
      model starting its history afresh; where the variant has no model at ``scale``, its model of the largest scale
      below, stretched (8x: XS 4x stretched 2x, 16x: XS 4x stretched 4x; :func:`auto_stretches`); otherwise 1;
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
      history per slab (docs/temporal.md, "Layered history"); only for a base-filter model on TAAU (XS) or a
      network trained on the layered TAAU (``taau_slabs``); 0 runs the TAAU on the frame's colour; None (the
      default) the model's own (:func:`~volsr_core.runtime.upscaler.default_slabs`: those it was trained on, two for
      the shipped XS 4x and U-Nets, else two for XS at 4x and more, else 0), and for a base-filter model (XS) by
      look: judged at each new history (as stretch "auto" judges), on its first frame rendered in the
      model's slabs, the model's count where at least :data:`MIXED_SHARE` of the frame's shown pixels mix two slabs
      (:func:`~volsr_core.render.slabs.mixed_share`), else one slab (that frame's slabs composited into one):
      :attr:`slabs` is the count of the last frame, :attr:`slabs_by_look` says whether it is chosen so.

    ``render(camera)`` returns float32 (H, W, 3) in [0, 1]; ``last_timings`` holds the ms spent
    rendering and upscaling that frame (``render_ms``, ``network_ms`` with the stretch, ``total_ms``: on the GPU
    until its work is done) and copying the image from the GPU (``readback_ms``, 0 on the host), ``last_frame`` the LR
    frame as rendered and ``last_low_resolution`` the same in host memory. :meth:`update` follows a changed volume,
    transfer function, background or size; :meth:`reset` drops the history for the caller's own reasons (the upscaler
    also drops it by itself on camera jumps, implausible motion and a new size). ``resets`` counts
    the drops, ``last_reset_reason`` says why the last one happened.
    """

    def __init__(self, volume: Volume, transfer_function: TransferFunction, model: Any = None, *,
                 scale: int | None = None, size: tuple[int, int] = (512, 512), variant: str | None = None,
                 device: str = "cpu",
                 backend: str = "auto", fp16: bool = False, threads: int | None = None,
                 sample_distance: float | None = None, background: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 max_turn: float = 30.0, max_zoom: float = 2.0, slabs: int | None = None, stretch: int | str = 1):
        # ray starts jittered per pixel and frame (seeded by the frame number): the temporal history averages
        # the offsets instead of keeping a fixed start's rings
        self._caster_options = {"sample_distance": sample_distance, "device": device, "start_jitter": "ign"}
        self.caster = RayCaster(volume, transfer_function, background=tuple(float(c) for c in background),
                                **self._caster_options)
        # one model and upscaler per stretch it may run: "auto" holds the unstretched and the stretched one
        self._paths: dict[int, tuple[Any, StatefulUpscaler]] = {}
        for k in _stretches(stretch, scale, model, variant):
            engine = _open_model(model, scale, k, variant, backend=backend, device=device, fp16=fp16, threads=threads)
            self._paths[k] = (engine, StatefulUpscaler(engine, max_turn=max_turn, max_zoom=max_zoom, slabs=slabs,
                                                       device=device, stretch=k))
        self.auto_stretch = len(self._paths) > 1
        self._by_look = {k: slabs is None and upscaler.base_filter is not None and upscaler.slabs > 1
                         for k, (_, upscaler) in self._paths.items()}
        self._look_slabs: int | None = None  # slabs by look: the count chosen for the current history
        self.max_turn = float(max_turn)  # a turn beyond it is a cut: stretch "auto" starts its choice afresh too
        self._fine = self._fast = False  # stretch "auto": the view samples the volume finely; it turns fast
        self._turns: deque[float] = deque(maxlen=TURN_FRAMES)  # ... the last frames' turns times pixels per voxel
        self._use(min(self._paths))
        self.size = (int(size[0]), int(size[1]))
        self._tf_key = _tf_key(transfer_function)
        self.frame = 0
        self.previous_camera: Camera | None = None
        self.last_timings: dict[str, float] = {}

    def _use(self, stretch: int) -> None:
        """Run the model and upscaler of ``stretch`` from the next frame (its history starts afresh)."""
        self.engine, self.upscaler = self._paths[stretch]
        if getattr(self, "stretch", stretch) != stretch:  # back to a history last used for other frames
            self.upscaler.reset("stretch changed")
            self._look_slabs = None
        self.stretch = stretch
        self.model_scale = int(self.engine.config.scale)
        self.scale = self.model_scale * stretch
        self.slabs = self.upscaler.slabs
        self.slabs_by_look = self._by_look[stretch]

    def _auto_stretch(self, camera: Camera, turn: float, starts: bool) -> int:
        """Stretch "auto"'s choice for the frame of ``camera``, which turned ``turn`` degrees since the last: 2 where
        the view samples the volume finely (judged where a history ``starts``: the first frame, or a turn beyond
        ``max_turn``, a cut) or turns fast for its sampling (with hysteresis, over the last frames' turns times their
        pixels per voxel), else 1."""
        pixels_per_voxel = self.caster.pixels_per_voxel(camera, self.size[1])
        if starts:
            self._fine = pixels_per_voxel >= STRETCH_FROM
            self._turns.clear()
            self._fast = False
        else:
            self._turns.append(turn * pixels_per_voxel)
            motion = statistics.median(self._turns)
            self._fast = motion >= FAST_TURN[1] or (self._fast and motion >= FAST_TURN[0])
        return 2 if self._fine or self._fast else 1

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
        turn = view_rotation(camera, self.previous_camera)
        starts = self.previous_camera is None or turn > self.max_turn  # a new history, or a cut (a jump, not a turn)
        if self.auto_stretch:
            self._use(self._auto_stretch(camera, turn, starts))
        judged = self.slabs_by_look and (starts or self._look_slabs is None)
        self.slabs = self.upscaler.slabs if judged or not self.slabs_by_look else self._look_slabs
        w, h = self.low_resolution_size
        jitter = halton_jitter(self.frame, jitter_phases(self.model_scale))
        started = time.perf_counter()
        lr = self.caster.render(camera, w, h, jitter=jitter, previous_camera=self.previous_camera, seed=self.frame,
                                slabs=self.slabs, on_device=self.upscaler.on_device)
        if judged:  # on the GPU the slabs come to the host and back, once a history
            slabs = to_host(lr.slabs)[0]
            self._look_slabs = self.slabs if mixed_share(slabs) >= MIXED_SHARE else 1
            if self._look_slabs < self.slabs:
                lr = dataclasses.replace(lr, slabs=placed_like(composited(slabs), lr.slabs))
                self.slabs = self._look_slabs
        rendered = time.perf_counter()
        image = self.upscaler.upscale(lr, self.caster.background)  # stretched by the upscaler of this stretch
        done = ready_at(image)
        image, readback_ms = to_host(image)
        self.last_timings = {"render_ms": 1000 * (rendered - started), "network_ms": 1000 * (done - rendered),
                             "total_ms": 1000 * (done - started), "readback_ms": readback_ms}
        self.last_frame = lr
        self.previous_camera = camera
        self.frame += 1
        return image[: self.size[1], : self.size[0]]


def auto_stretches(scale: int | None, variant: str | None) -> tuple[int, ...]:
    """The stretches ``stretch="auto"`` chooses between for the shipped models at ``scale`` (None: the default scale)
    and ``variant`` (None: the fastest variant, XS, wherever it ships): the least k of 1, 2, 4, ... (k divides
    ``scale``, ``scale`` / k at least 2) at whose scale / k the variant ships, and with it 2k where k is 1 and the
    variant ships at half the scale too (4x: XS 4x, or XS 2x stretched where the view asks for it). So a scale the
    variant does not ship runs its model of the largest scale below, stretched: 8x XS 4x + bicubic 2x (the one 8x
    model is a U-Net, 2.5-3.8 times as slow as XS 4x stretched in every run of docs/bench and below the native +
    bilinear curve in all, where XS 4x stretched lies above it in half: docs/performance.md, "How fast the view
    turns"), 16x XS 4x + bicubic 4x (docs/performance.md, "16x"); a
    named variant that ships at no such scale gets (1,), whose model the pipeline then fails to find, naming what
    ships."""
    if scale is None or scale < 4:
        return (1,)
    from volsr_core.runtime.models import shipped_models

    shipped = {(e["variant"], e["scale"]) for e in shipped_models()}
    for wanted in [variant.upper()] if variant else VARIANTS:
        ships = [k for k in stretch_steps(scale) if (wanted, scale // k) in shipped]
        if ships:
            least = ships[0]
            return (1, 2) if least == 1 and 2 in ships else (least,)
    return (1,)


def stretch_steps(scale: int) -> list[int]:
    """The stretches a model's image may take at ``scale`` (the whole factor from the LR frame to the output): 1, 2, 4,
    ... where they divide ``scale`` and leave the model at least 2x."""
    return [k for k in (2 ** i for i in range(scale.bit_length())) if scale % k == 0 and scale // k >= 2]


def _stretches(stretch: int | str, scale: int | None, model: Any, variant: str | None) -> tuple[int, ...]:
    """The stretches a pipeline may run: ``stretch`` itself, or for "auto" :func:`auto_stretches` (1 for a given
    model)."""
    if stretch == "auto":
        return (1,) if model is not None else auto_stretches(scale, variant)
    if not isinstance(stretch, int) or stretch < 1 or (scale is not None and (scale % stretch or scale < 2 * stretch)):
        raise ValueError("the stretch must be 'auto' or a whole number >= 1 that divides the scale and leaves the "
                         f"model at least 2x, got {stretch!r}" + ("" if scale is None else f" for {scale}x"))
    return (stretch,)


def _open_model(model: Any, scale: int | None, stretch: int, variant: str | None, **options: Any):
    """The engine for ``model`` (None: the shipped one of ``variant`` at ``scale`` / ``stretch``, or at
    :data:`~volsr_core.runtime.models.DEFAULT_SCALE`); a model of another scale than ``scale`` / ``stretch`` is an
    error."""
    model_scale = None if scale is None else scale // stretch
    if model is None:
        from volsr_core.runtime.models import DEFAULT_SCALE, default_variant, model_file, model_file_to_run

        model_scale = DEFAULT_SCALE if model_scale is None else model_scale
        variant = variant or default_variant(model_scale)
        model = (model_file(variant, model_scale, "pt") if options["backend"] == "torch"
                 else model_file_to_run(variant, model_scale, options["device"]))
    engine = open_engine(model, **options)
    if model_scale is not None and engine.config.scale != model_scale:
        raise ValueError(f"the model upscales {engine.config.scale}x, not {model_scale}x"
                         + (f" ({scale}x stretched {stretch}x)" if stretch > 1 else ""))
    return engine


def _tf_key(tf: TransferFunction) -> str:
    """A transfer function's definition as text: equal texts, equal functions."""
    return json.dumps(tf.to_dict(), sort_keys=True)
