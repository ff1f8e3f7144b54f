"""The ways to make a full-size frame that VolSR is measured against, one object each: camera in, image out.

Every method renders one frame per call along a camera path (the temporal ones keep their history)
and returns a :class:`MethodFrame`: the (H, W, 3) float32 image in [0, 1] (H, W = ``size``) and the
ms spent ray casting and upscaling. With a ray caster on "cuda" every method makes its full-size image on the
GPU, where a viewer shows it (the baseline's stretch too, as VTK's), and its times end when the GPU is done; the
image's copy to the host, the same for every method, is timed apart (``ms_readback``).

- :class:`Native`: full size, ``spp`` Halton-jittered samples per pixel averaged (1: the pixel
  centres, no jitter);
- :class:`ReducedSize`: round(size / ``factor``), pixel centres, no jitter, upscaled to full size by
  bilinear interpolation (what VTK's ImageSampleDistance and 3D Slicer show while interacting) or
  bicubic (the super-resolution papers' baseline);
- :class:`Taau`: size / ``scale`` with Halton jitter and motion vectors, accumulated by the TAAU a
  TAAU-based network refines (:func:`~volsr_core.sr.history.taau_upsampler`), or with ``slabs`` K by
  the layered TAAU (:class:`~volsr_core.temporal.layered.LayeredUpsampler`) on K depth slabs;
- :class:`VolSR`: a :class:`~volsr_core.runtime.pipeline.Pipeline` (LR render + network).

``volsr bench`` runs them side by side, ``volsr upscale --side-by-side`` draws them as panels, and
``volsr eval`` uses their upscaling stages alone (:meth:`ReducedSize.upscale`, :meth:`Taau.upscale`)
on the LR frames a dataset stores.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from volsr_core.render.device import ready_at, to_host
from volsr_core.render.features import FeatureFrame
from volsr_core.render.raycaster import RayCaster
from volsr_core.scene.camera import Camera
from volsr_core.sr.history import taau_upsampler
from volsr_core.temporal.jitter import halton_jitter, jitter_phases
from volsr_core.temporal.layered import LayeredUpsampler
from volsr_core.temporal.resample import resize_bicubic, resize_bilinear
from volsr_core.temporal.supersample import render_supersampled
from volsr_core.temporal.taau import view_rotation

INTERPOLATIONS = ("bilinear", "bicubic")


@dataclass
class MethodFrame:
    """One frame of a method: the image and where its time went (ms)."""

    image: np.ndarray
    ms_render: float
    ms_upscale: float = 0.0
    # the LR frame rendered, for methods that render one with features; as rendered: on the GPU where the method
    # keeps it there (FeatureFrame.to_host copies it back when someone reads it)
    low_resolution: FeatureFrame | None = None
    # the copy of the full-size image from the GPU to the host, not in ms_total (0 where it was made on the host)
    ms_readback: float = 0.0

    @property
    def ms_total(self) -> float:
        return self.ms_render + self.ms_upscale


class Method:
    """Base of the comparison methods: ``method(camera)`` -> :class:`MethodFrame`; :meth:`reset` is a cut.

    ``kind`` ("native", "bilinear", "bicubic", "taau", "volsr"), ``scale`` (the size reduction; 1 for
    native), ``spp``, ``slabs`` (the depth slabs rendered: TAAU and VolSR on a layered history), ``stretch`` (VolSR:
    the bilinear factor after the model, which upscales ``scale`` / ``stretch``), ``variant`` and ``model`` (VolSR)
    describe it; ``label`` names it in reports.
    """

    kind = ""
    scale = 1
    spp = 1
    slabs = 0
    stretch = 1
    variant: str | None = None
    model: str | None = None

    def __init__(self, size: tuple[int, int]):
        self.size = (int(size[0]), int(size[1]))

    @property
    def label(self) -> str:
        raise NotImplementedError

    def __call__(self, camera: Camera) -> MethodFrame:
        raise NotImplementedError

    def reset(self) -> None:
        """Forget the history (no-op for methods without one)."""


def _on_device(caster: RayCaster | None) -> bool:
    return getattr(caster, "device", "cpu") == "cuda"


class Native(Method):
    """Full size, ``spp`` Halton-jittered samples per pixel (:func:`render_supersampled`)."""

    kind = "native"

    def __init__(self, caster: RayCaster, size: tuple[int, int], spp: int = 1):
        super().__init__(size)
        self.caster, self.spp = caster, int(spp)
        self.frame = 0

    @property
    def label(self) -> str:
        return f"native {self.spp} spp"

    def __call__(self, camera: Camera) -> MethodFrame:
        started = time.perf_counter()
        image = render_supersampled(self.caster, camera, *self.size, spp=self.spp, seed=self.frame * self.spp,
                                    on_device=_on_device(self.caster))
        rendered = ready_at(image)
        self.frame += 1
        image, ms_readback = to_host(image)
        return MethodFrame(image, 1000.0 * (rendered - started), ms_readback=ms_readback)


class ReducedSize(Method):
    """round(size / ``factor``) pixels at their centres, upscaled to ``size`` by ``interpolation``;
    ``factor`` need not be whole (VTK's ImageSampleDistance is not)."""

    def __init__(self, caster: RayCaster | None, size: tuple[int, int], factor: float,
                 interpolation: str = "bilinear"):
        super().__init__(size)
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
        self.caster, self.kind = caster, interpolation
        self.scale = int(factor) if float(factor).is_integer() else float(factor)
        self.frame = 0
        self.on_device = interpolation == "bilinear" and _on_device(caster)  # a bicubic stretch runs on the host
        if self.on_device:
            from volsr_core.temporal.frames_cuda import resize_bilinear_device

            self._resize_on_device = resize_bilinear_device

    @property
    def label(self) -> str:
        return f"native 1/{self.scale:g} size + {self.kind}"

    @property
    def low_resolution_size(self) -> tuple[int, int]:
        return max(1, round(self.size[0] / self.scale)), max(1, round(self.size[1] / self.scale))

    def upscale(self, colour: np.ndarray) -> np.ndarray:
        """The upscaling stage alone: an (h, w, 3) colour image stretched over ``size`` (the same view at
        every size, as VTK stretches a reduced rendering over the viewport); bicubic clipped to [0, 1]."""
        width, height = self.size
        if self.kind == "bilinear":
            return resize_bilinear(colour, width, height)
        return resize_bicubic(colour, width, height, clamp=(0.0, 1.0))

    def __call__(self, camera: Camera) -> MethodFrame:
        started = time.perf_counter()
        lr = self.caster.render_color(camera, *self.low_resolution_size, seed=self.frame,  # the colour alone, as VTK
                                      on_device=self.on_device)
        rendered = time.perf_counter()
        if self.on_device:
            image = self._resize_on_device(lr, *self.size)
        else:
            image = self.upscale(lr)
        done = ready_at(image)
        self.frame += 1
        image, ms_readback = to_host(image)
        return MethodFrame(image, 1000.0 * (rendered - started), 1000.0 * (done - rendered), ms_readback=ms_readback)


class Taau(Method):
    """size / ``scale``, Halton-jittered (``halton_jitter(frame, jitter_phases(scale))``), with motion
    vectors to the previous camera, accumulated by :func:`~volsr_core.sr.history.taau_upsampler`; with
    ``slabs`` K > 0 rendered in K depth slabs and accumulated by the layered TAAU (one history per slab). With a
    ray caster on "cuda" the frame stays on the GPU and the TAAU runs there (:mod:`volsr_core.temporal.cuda`), as
    VolSR XS's does; the image is copied back after the timed step."""

    kind = "taau"

    def __init__(self, caster: RayCaster | None, size: tuple[int, int], scale: int, slabs: int = 0):
        super().__init__(size)
        self.caster, self.scale, self.slabs = caster, int(scale), int(slabs)
        self.on_device = _on_device(caster)
        if self.on_device:
            from volsr_core.temporal.cuda import CudaLayeredUpsampler, CudaTemporalUpsampler

            self.upsampler = CudaLayeredUpsampler(self.scale) if self.slabs else CudaTemporalUpsampler(self.scale)
        else:
            self.upsampler = LayeredUpsampler(self.scale) if self.slabs else taau_upsampler(self.scale,
                                                                                          side_outputs=False)
        self.frame = 0
        self.previous: Camera | None = None

    @property
    def label(self) -> str:
        return f"TAAU {self.scale}x in {self.slabs} slabs" if self.slabs else f"TAAU {self.scale}x"

    @property
    def low_resolution_size(self) -> tuple[int, int]:
        return self.size[0] // self.scale, self.size[1] // self.scale

    def reset(self) -> None:
        self.upsampler.reset()
        self.previous = None

    def upscale(self, colour: np.ndarray, motion: np.ndarray, jitter: tuple[float, float],
                depth: np.ndarray | None = None, rotation: float | None = None,
                pixels_per_voxel: float | None = None) -> np.ndarray:
        """The accumulation stage alone: one jittered LR frame (colour, motion, jitter, the reprojected
        point's depth, the view's rotation in degrees since the last frame, the frame's pixels per
        voxel) in, (H, W, 3) out. Not for a layered TAAU, which takes the frame's depth slabs."""
        if self.slabs:
            raise ValueError("a layered TAAU upscales depth slabs, not a colour image: call it on a camera")
        image = self.upsampler(colour, motion, jitter, depth, rotation, pixels_per_voxel)
        return image.copy_to_host() if self.on_device else image

    def __call__(self, camera: Camera) -> MethodFrame:
        width, height = self.size
        jitter = halton_jitter(self.frame, jitter_phases(self.scale))
        started = time.perf_counter()
        lr = self.caster.render(camera, width // self.scale, height // self.scale, jitter=jitter,
                                previous_camera=self.previous, seed=self.frame, slabs=self.slabs,
                                on_device=self.on_device)
        rendered = time.perf_counter()
        rotation = view_rotation(camera, self.previous)
        if self.slabs:
            image = self.upsampler(lr.slabs, lr.jitter, self.caster.background, rotation, lr.pixels_per_voxel)
        else:
            image = self.upsampler(lr.color, lr.motion, lr.jitter, lr.motion_depth, rotation, lr.pixels_per_voxel)
        done = ready_at(image)
        self.frame += 1
        self.previous = camera
        image, ms_readback = to_host(image)
        return MethodFrame(image, 1000.0 * (rendered - started), 1000.0 * (done - rendered), lr, ms_readback)


class VolSR(Method):
    """The learned path: a :class:`~volsr_core.runtime.pipeline.Pipeline` renders and upscales."""

    kind = "volsr"

    def __init__(self, pipeline: Any, variant: str | None = None, model: str | None = None):
        super().__init__(pipeline.size)
        self.pipeline, self.scale = pipeline, int(pipeline.scale)
        self.stretch = int(getattr(pipeline, "stretch", 1))  # a frame-budget renderer has none of its own
        self.variant, self.model = variant, model

    @property
    def slabs(self) -> int:
        """The depth slabs the pipeline rendered its last frame in (0: none, the TAAU on the frame's colour; a
        frame-budget renderer, whose levels differ, has none of its own)."""
        return getattr(self.pipeline, "slabs", 0)

    @property
    def label(self) -> str:
        """'VolSR XS 4x in 2 slabs', 'VolSR XS 4x in 1 or 2 slabs' where the pipeline chooses them by look
        (``Pipeline.slabs_by_look``); a stretched pipeline names its model's scale and the stretch: 'VolSR XS 2x +
        bicubic 2x' is a 4x point."""
        if getattr(self.pipeline, "slabs_by_look", False):
            slabs = f" in 1 or {self.pipeline.upscaler.slabs} slabs"
        else:
            slabs = f" in {self.slabs} slabs" if self.slabs else ""
        stretch = f" + bicubic {self.stretch}x" if self.stretch > 1 else ""
        return f"VolSR {self.variant} {self.scale // self.stretch}x{slabs}{stretch}"

    def reset(self) -> None:
        self.pipeline.reset()

    def __call__(self, camera: Camera) -> MethodFrame:
        image = self.pipeline.render(camera)
        timings = self.pipeline.last_timings
        return MethodFrame(image, timings["render_ms"], timings["network_ms"], self.pipeline.last_frame,
                           timings.get("readback_ms", 0.0))
