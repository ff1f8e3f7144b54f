"""StatefulUpscaler: one LR feature frame in, one HR frame out, the temporal history kept inside.

Every rule for dropping the history lives here: a new size, implausible motion and a camera jump
(:func:`camera_jump`), besides :meth:`StatefulUpscaler.reset` for the caller's own reasons.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any, Sequence

import numba
import numpy as np

from volsr_core.render.features import FeatureFrame
from volsr_core.runtime.base_filter import Scratch, filter_image
from volsr_core.runtime.content_window import content_window, shows_nearby
from volsr_core.runtime.layout import clip_with_window, to_channels_first, to_image_clipped
from volsr_core.scene.camera import Camera, rotation_between
from volsr_core.sr.history import HistoryFeed, history_mode
from volsr_core.temporal.resample import resize_bicubic, upscale_bilinear
from volsr_core.temporal.taau import view_rotation


def network_inputs(frame: FeatureFrame, features: tuple[str, ...]) -> np.ndarray:
    """(C, h, w) float32: the frame's buffers named by ``features``, stacked as the network takes them."""
    planes = []
    for name in features:
        buffer = np.asarray(getattr(frame, name), dtype=np.float32)
        planes.append(buffer[..., None] if buffer.ndim == 2 else buffer)
    return np.ascontiguousarray(np.concatenate(planes, axis=-1).transpose(2, 0, 1))


@numba.njit(cache=True)
def _motion_statistics(sample: np.ndarray, step: int, h: int, w: int, limit: float) -> tuple[float, float]:
    """Over a motion buffer's every ``step``-th pixel each way, ``sample`` (rows, cols, 2) = ``motion[::step,
    ::step]`` of an (h, w, 2) buffer (LR px, from the pixel centre): the fraction of vectors longer than ``limit``
    (LR px; over a half: the median vector, the lower middle one of an even count, is longer) and the fraction that
    point off the frame, in one numba loop (a 128² frame's strided sample: 6 µs a call, where its median took 11 and
    numpy's passes 109)."""
    rows, cols = sample.shape[0], sample.shape[1]
    limit_squared = limit * limit
    longer = off = 0
    for j in range(rows):
        for i in range(cols):
            mx, my = sample[j, i, 0], sample[j, i, 1]
            if mx * mx + my * my > limit_squared:
                longer += 1
            x, y = i * step + 0.5 + mx, j * step + 0.5 + my
            if x < 0 or x > w or y < 0 or y > h:
                off += 1
    return longer / (rows * cols), off / (rows * cols)


def _no_motion(shape: tuple[int, ...]) -> np.ndarray:
    """Zero motion vectors of ``shape`` (h, w, 2), strided as a frame's own are (two channels of a wider buffer): a
    contiguous array would have TAAU's kernels compiled a second time for its layout (7 s at first use, 2 cores)."""
    return np.zeros(tuple(shape[:2]) + (3,), np.float32)[..., :2]


def camera_jump(previous: Camera | None, camera: Camera, max_turn: float = 30.0, max_zoom: float = 2.0) -> str:
    """Why ``camera`` is a cut from ``previous`` rather than a drag ("" when it is not): a switched
    projection, a changed view angle, a turn of more than ``max_turn`` degrees, or a distance (parallel
    scale) changed by more than ``max_zoom`` times."""
    if previous is None:
        return ""
    if previous.parallel_projection != camera.parallel_projection:
        return "projection switched"
    if not camera.parallel_projection and abs(camera.view_angle - previous.view_angle) > 1e-9:
        return "view angle changed"
    if rotation_between(previous, camera) > max_turn:
        return "camera turned"
    ratio = (camera.parallel_scale / previous.parallel_scale if camera.parallel_projection
             else camera.distance / previous.distance)
    if max(ratio, 1.0 / ratio) > max_zoom:
        return "zoom jump"
    return ""


STRETCH_CUBIC_A = -0.75  # Keys' a of the stretch (PyTorch's, OpenCV's): the best of -0.5..-1.5, docs/performance.md
LAYERED_SLABS = 2  # depth slabs of the layered TAAU where it is the default (docs/temporal.md, "Layered history")
LAYERED_FROM_SCALE = 4  # the smallest scale it is the default at: at 2x TAAU's own history is the better one


def takes_slabs(engine: Any) -> bool:
    """Whether ``engine``'s model can refine the layered TAAU: a model whose history is a TAAU estimate of colour
    alone (no side outputs) that is a base filter (variant XS, no U-Net), which may take any TAAU, or a U-Net trained
    on the layered TAAU (``taau_slabs``), whichever engine runs it (the CPU kernel, onnxruntime, torch, a GPU)."""
    config = engine.config
    refines = not config.widths or getattr(config, "taau_slabs", 0) > 0  # a U-Net only where it was trained on slabs
    return refines and history_mode(config) == "taau" and not getattr(config, "taau_aux", False)


def default_slabs(engine: Any) -> int:
    """The depth slabs ``engine``'s model runs on when the caller names none: those it was fitted on (its config's
    ``taau_slabs``), else :data:`LAYERED_SLABS` where it can refine the layered TAAU (:func:`takes_slabs`) at
    :data:`LAYERED_FROM_SCALE` or more, 0 (the TAAU) otherwise.

    Measured (docs/performance.md, "the layered TAAU"): at 4x two slabs lift VolSR XS against the native + bilinear
    curve on all four bench volumes at 512² and 1024² and four cost more render time than they give; at 8x two
    lift TAAU by 0.9-1.1 dB; at 2x the layered history is below TAAU's."""
    if not takes_slabs(engine):
        return 0
    fitted_on = getattr(engine.config, "taau_slabs", 0)
    return fitted_on or (LAYERED_SLABS if engine.config.scale >= LAYERED_FROM_SCALE else 0)


WINDOW_SHARE = 0.8
"""A content window (:func:`~volsr_core.runtime.content_window.content_window`) holding more than this share of a
frame's LR pixels runs the network on the whole frame."""


class StatefulUpscaler:
    """Feeds an engine (:mod:`volsr_core.runtime.engines`) frame by frame, as a viewer renders them.

    ``upscale(frame)`` takes one LR :class:`FeatureFrame` (rendered with jitter and the previous
    camera, so its motion vectors point into the previous frame) and returns the (H, W, 3) float32
    image in [0, 1], H = h * scale * stretch. It keeps the last N frames and the network's history
    (:class:`~volsr_core.sr.history.HistoryFeed`: its previous output, or the TAAU estimate it
    refines). The history is dropped (the next frame starts afresh) when:

    - fewer than N frames came before: the missing ones repeat the oldest frame held, with zero
      motion (a still camera), so the first frame works;
    - :meth:`reset` is called (a camera cut, a new volume or transfer function);
    - the LR size changes (a resized window);
    - the camera jumped (:func:`camera_jump` with ``max_turn`` degrees and ``max_zoom``);
    - the motion is implausibly large: the median vector longer than ``max_motion`` times the
      frame's diagonal in LR pixels (a jump, not a drag), or more than ``max_offscreen`` of the
      pixels reprojecting off screen.

    ``resets`` counts the drops and ``last_reset_reason`` says why the last one happened.

    ``slabs`` K > 0 (a model that :func:`takes_slabs`: variant XS on TAAU, or a U-Net trained on slabs) runs the
    layered TAAU (:class:`~volsr_core.temporal.layered.LayeredUpsampler`) on frames rendered in K depth slabs
    (``RayCaster.render(..., slabs=K)``) instead of the TAAU on their colour, and the model on its estimate;
    0 runs the TAAU; None (the default) takes :func:`default_slabs` of the engine.

    ``stretch`` k > 1 returns the images stretched by k (a model at 1/k of the output size: ``Pipeline(...,
    stretch=k)``), by Keys' cubic convolution with :data:`STRETCH_CUBIC_A`, clamped to [0, 1]; on the CPU variant XS's
    filter does a stretch by 2 in its own passes (:func:`~volsr_core.runtime.base_filter.filter_image`).

    ``device`` "cuda" keeps such a model's work on the GPU (:attr:`on_device`): it takes frames rendered there
    (``RayCaster.render(..., on_device=True)``), runs the TAAU and the filter as CUDA kernels and returns the
    (H, W, 3) result there, a device array for the caller to copy back (``Pipeline`` does, after timing the step).
    Other models, and every model on the CPU, take host frames and return host images.

    ``skip_background`` (the default) runs a TAAU-based network without previous frames on the window of the frame
    where the volume or its TAAU estimate shows (:func:`~volsr_core.runtime.content_window.content_window`, a
    margin around it) and takes the estimate, the background, outside it; the whole frame when the window holds
    most of it (more than :data:`WINDOW_SHARE` of its pixels), none where nothing shows. For a U-Net the estimate
    stays inside the window too where the frame shows nothing within
    :data:`~volsr_core.runtime.content_window.NEARBY` LR pixels
    (:func:`~volsr_core.runtime.content_window.shows_nearby`): there its output is the residual of a background it
    was never trained on, a tint up to 0.058 on a light one. False runs the network on every pixel and takes
    its output everywhere, as it did before 2026-11-29. :attr:`last_window` holds the last frame's window in LR
    pixels (top, bottom, left, right; bottom and right exclusive).
    """

    def __init__(self, engine: Any, max_motion: float = 0.25, max_offscreen: float = 0.5, max_turn: float = 30.0,
                 max_zoom: float = 2.0, slabs: int | None = None, device: str = "cpu", stretch: int = 1,
                 skip_background: bool = True):
        if stretch < 1 or int(stretch) != stretch:
            raise ValueError(f"the stretch must be a whole number >= 1, got {stretch!r}")
        self.stretch = int(stretch)
        self.engine = engine
        self.config = engine.config
        self.max_motion, self.max_offscreen = float(max_motion), float(max_offscreen)
        self.max_turn, self.max_zoom = float(max_turn), float(max_zoom)
        self.frames: deque[tuple[np.ndarray, np.ndarray, np.ndarray]] = deque(maxlen=self.config.previous_frames + 1)
        self.base_filter = getattr(engine, "base_filter", None)  # variant XS on the CPU: no network inputs
        self.slabs = default_slabs(engine) if slabs is None else int(slabs)
        if self.slabs < 0:
            raise ValueError(f"depth slabs must be 0 or more, got {self.slabs}")
        if self.slabs and not takes_slabs(engine):
            raise ValueError("depth slabs feed a layered TAAU, which only a base-filter model on TAAU (variant XS) "
                             "or a network trained on it (taau_slabs) refines")
        # on a GPU a base filter on TAAU (variant XS) runs where the frame was rendered: TAAU, filter and all
        self.on_device = device == "cuda" and self.base_filter is not None and takes_slabs(engine)
        # the layered TAAU on the frames' slabs, or the TAAU on their colour, whichever the model was fitted on
        self.history = HistoryFeed(self.config, slabs=self.slabs, device="cuda" if self.on_device else "cpu")
        self._device_filter = self._device_scratch = None
        if self.on_device:
            from volsr_core.runtime.base_filter_cuda import CudaBaseFilter, DeviceScratch

            self._device_filter = CudaBaseFilter(*self.base_filter)
            self._device_scratch = DeviceScratch()  # on the GPU: TAAU's estimate, the camera-cut check's sample
        self._scratch = Scratch()  # work buffers kept between frames: the base filter's, the network's history
        # a network that refines TAAU's estimate from the current frame alone reads nothing outside its receptive field
        self.skip_background = (bool(skip_background) and history_mode(self.config) == "taau"
                                and self.config.previous_frames == 0)
        # the LR window the network last ran on (bottom and right exclusive; (0, 0, 0, 0): nowhere), None before
        self.last_window: tuple[int, int, int, int] | None = None
        self.resets = 0
        self.last_reset_reason = ""

    def reset(self, reason: str = "asked") -> None:
        """Forget every previous frame and output."""
        self.frames.clear()
        self.history.reset()
        self.resets += 1
        self.last_reset_reason = reason

    def _motion_sample(self, motion) -> tuple[Any, int]:
        """(every ``step``-th vector each way, step): about 64 x 64 of them, frame-wide fractions that need no more,
        at a sixteenth of the cost on a 256² frame. On the GPU the sample is gathered there into a device array, its
        copy to the host left to the caller."""
        step = max(1, min(motion.shape[0], motion.shape[1]) // 64)
        if hasattr(motion, "copy_to_host"):
            from volsr_core.runtime.base_filter_cuda import every_nth

            return every_nth(motion, step, self._device_scratch), step
        return motion[::step, ::step], step

    def _implausible(self, sample: np.ndarray, step: int, shape: tuple[int, ...]) -> str:
        """Why the motion of a frame of ``shape`` (h, w, 2) cannot be followed, by its :meth:`_motion_sample` ("" when
        it can): a median vector over a quarter of the frame's diagonal, or most vectors off the frame."""
        h, w = shape[:2]
        longer, offscreen = _motion_statistics(sample, step, h, w, self.max_motion * math.hypot(h, w))
        if longer > 0.5:  # the median vector is longer than that
            return "large motion"
        if offscreen > self.max_offscreen:
            return "motion leaves the screen"
        return ""

    def _camera_cut(self, frame: FeatureFrame, inputs) -> str:
        """What of :meth:`_cut` the host knows without the motion: a new size, a camera jump."""
        if self.frames[0][0].shape != inputs.shape:
            return "size changed"
        return camera_jump(frame.previous_camera, frame.camera, self.max_turn, self.max_zoom)

    def _cut(self, frame: FeatureFrame, inputs) -> str:
        """Why the history must go before ``frame`` ("" to keep it): a host frame's (a frame on the GPU is checked by
        :meth:`_filtered`, which reads its sample after queuing its kernels)."""
        reason = self._camera_cut(frame, inputs)
        if reason:
            return reason
        return self._implausible(*self._motion_sample(frame.motion), frame.motion.shape)

    def _continues(self, frame: FeatureFrame, inputs: np.ndarray) -> bool:
        """Whether ``frame`` continues the frames held: drops them first when it is a cut (:meth:`_cut`)."""
        if self.frames:
            reason = self._cut(frame, inputs)
            if reason:
                self.reset(reason)
        return bool(self.frames)

    def upscale(self, frame: FeatureFrame, background: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """The HR image for ``frame`` (see the class); float32 (H, W, 3) in [0, 1], a device array where
        :attr:`on_device`. ``background``: the RGB the renderer composited over, which the layered TAAU composites its
        slabs over."""
        if self.base_filter is not None:
            return self._filtered(frame, background)
        if self.skip_background:
            return self._refined(frame, background)
        inputs = network_inputs(frame, self.config.features)
        motion = np.ascontiguousarray(frame.motion, dtype=np.float32).transpose(2, 0, 1)
        jitter = np.asarray(frame.jitter, dtype=np.float32)
        if not self._continues(frame, inputs):
            motion = np.zeros_like(motion)  # nothing to warp from: the motion points into no frame we hold
        self.frames.appendleft((inputs, motion, jitter))
        held = list(self.frames)
        oldest = held[-1]
        while len(held) < self.config.previous_frames + 1:
            held.append((oldest[0], np.zeros_like(oldest[1]), oldest[2]))
        lr = np.stack([f[0] for f in held])[None]
        vectors = np.stack([f[1] for f in held])[None]
        jitters = np.stack([f[2] for f in held])[None]
        parts = self.history.parts(frame.color, motion.transpose(1, 2, 0), tuple(jitter), frame.motion_depth,
                                   view_rotation(frame.camera, frame.previous_camera), frame.pixels_per_voxel,
                                   slabs=frame.slabs, background=background)
        history = None
        if parts is not None:  # (1, C, H, W) in a buffer kept between frames: the engine reads it during the call
            shape = (sum(part.shape[2] for part in parts),) + parts[0].shape[:2]
            history = to_channels_first(parts, self._scratch.get("history", shape))[None]
        out = self.engine(lr, vectors, jitters, history)[0]  # (3, H, W)
        self.history.keep(out.transpose(1, 2, 0))
        return self._stretched(to_image_clipped(out))

    def _window_buffer(self, name: str, shape: tuple[int, ...], frame_size: int) -> np.ndarray:
        """A contiguous float32 array of ``shape`` at the start of the kept buffer ``name`` of ``frame_size`` floats
        (the whole frame's, what a window holds at most): windows of every size share it, no new array a frame."""
        return self._scratch.get(name, (frame_size,))[:math.prod(shape)].reshape(shape)

    def _refined(self, frame: FeatureFrame, background: Sequence[float]) -> np.ndarray:
        """:meth:`upscale` for a TAAU-based network without previous frames (:attr:`skip_background`): TAAU's
        estimate, the network run on the frame's content window alone (see the class; the whole frame where the
        window holds more than :data:`WINDOW_SHARE` of it) and its output written over the estimate there (a U-Net's
        only where the frame shows something within :data:`~volsr_core.runtime.content_window.NEARBY` LR pixels),
        clipped to [0, 1] with it in one pass. The network's inputs, history and output are the window's alone, laid
        out channels first from views of the frame's buffers and the estimate into buffers kept between frames."""
        colour, scale = frame.color, self.config.scale
        motion = frame.motion if self._continues(frame, colour) else _no_motion(frame.motion.shape)
        jitter = np.asarray(frame.jitter, dtype=np.float32)
        self.frames.appendleft((colour, motion, jitter))
        parts = self.history.parts(colour, motion, tuple(frame.jitter), frame.motion_depth,
                                   view_rotation(frame.camera, frame.previous_camera), frame.pixels_per_voxel,
                                   slabs=frame.slabs, background=background)
        estimate = parts[0]  # (H, W, 3), a new array each frame (the TAAU keeps its own history): the image returned
        h, w = colour.shape[:2]
        # the layered TAAU's estimate is the background away from the frame's alpha: only a one-layer TAAU's is read
        top, bottom, left, right = content_window(frame.alpha, None if self.slabs else estimate.transpose(2, 0, 1),
                                                  background, scale)
        if (bottom - top) * (right - left) > WINDOW_SHARE * h * w:
            top, bottom, left, right = 0, h, 0, w
        self.last_window = (top, bottom, left, right)
        if bottom <= top or right <= left:  # nothing shows: the estimate is the background
            clip_with_window(estimate, np.empty((3, 0, 0), np.float32))
            return self._stretched(estimate)
        rows, columns = slice(top, bottom), slice(left, right)
        hr_rows, hr_columns = slice(top * scale, bottom * scale), slice(left * scale, right * scale)
        planes = [np.asarray(getattr(frame, name))[rows, columns] for name in self.config.features]
        planes = [plane[..., None] if plane.ndim == 2 else plane for plane in planes]
        window, hr_window = (bottom - top, right - left), ((bottom - top) * scale, (right - left) * scale)
        lr_channels, hr_channels = sum(plane.shape[2] for plane in planes), sum(part.shape[2] for part in parts)
        lr = to_channels_first(planes, self._window_buffer("lr", (lr_channels,) + window, lr_channels * h * w))
        vectors = to_channels_first([motion[rows, columns]], self._window_buffer("motion", (2,) + window, 2 * h * w))
        history = to_channels_first([part[hr_rows, hr_columns] for part in parts], self._window_buffer(
            "history", (hr_channels,) + hr_window, hr_channels * h * w * scale * scale))
        out = self.engine(lr[None, None], vectors[None, None], jitter[None, None], history[None])[0]
        # a U-Net's residual where nothing shows nearby is a tint; a base filter alone (XS through its graph) keeps its
        # output there, as its kernel does
        where = shows_nearby(frame.alpha, (top, bottom, left, right)) if self.config.widths else None
        image = clip_with_window(estimate, out, top * scale, left * scale, where=where, scale=scale)
        self.history.keep(image)
        return self._stretched(image)

    def _stretched(self, image):
        """``image`` (H, W, 3) stretched by :attr:`stretch` (Keys' cubic, :data:`STRETCH_CUBIC_A`, clamped to [0, 1])
        where it lies, on the GPU or in host memory; as it is at stretch 1."""
        if self.stretch == 1:
            return image
        height, width = image.shape[0] * self.stretch, image.shape[1] * self.stretch
        if self.on_device:
            from volsr_core.temporal.frames_cuda import resize_bicubic_device

            return resize_bicubic_device(image, width, height, a=STRETCH_CUBIC_A, clamp=(0.0, 1.0))
        return resize_bicubic(image, width, height, a=STRETCH_CUBIC_A, clamp=(0.0, 1.0))

    def _filtered(self, frame: FeatureFrame, background: Sequence[float]) -> np.ndarray:
        """:meth:`upscale` for a network that is only its base filter, run by the engine's CPU kernel
        (:func:`~volsr_core.runtime.base_filter.filter_image`) on TAAU's (H, W, 3) estimate as it comes, or on the
        GPU by its kernels there.

        On the GPU a frame that continues the held ones by the camera has its motion sample gathered, its TAAU and
        filter queued, and only then the sample read: the host waits for the device once, as the frame ends, not
        between the render and the kernels after it. Where the sample says the motion cannot be followed (rare: the
        camera check passed) the frame is made again without its history, as it would have been."""
        colour = frame.color  # a view into the renderer's buffer, read in place by TAAU
        if self.on_device and self.frames:
            reason = self._camera_cut(frame, colour)
            if reason:
                self.reset(reason)
            else:
                sample, step = self._motion_sample(frame.motion)
                image = self._filtered_frame(frame, frame.motion, background)
                reason = self._implausible(sample.copy_to_host(), step, frame.motion.shape)
                if not reason:
                    return image
                self.reset(reason)
        motion = frame.motion if self._continues(frame, colour) else _no_motion(frame.motion.shape)
        return self._filtered_frame(frame, motion, background)

    def _filtered_frame(self, frame: FeatureFrame, motion, background: Sequence[float]):
        """:meth:`_filtered` for ``frame`` with ``motion`` (its own, or zeros after a cut)."""
        colour = frame.color
        self.frames.appendleft((colour, motion, np.asarray(frame.jitter, dtype=np.float32)))
        rotation = view_rotation(frame.camera, frame.previous_camera)
        # the layered TAAU is told the pixels per voxel whatever the model's TAAU is told: XS 4x's filter on the told
        # layered estimate beat it on the untold one by 0.7-1.9 dB at 1024² (docs/temporal.md, "Layered history")
        # the estimate goes into a buffer kept between frames (on the GPU where the frame is): the filter reads it and
        # keeps nothing
        shape = (colour.shape[0] * self.config.scale, colour.shape[1] * self.config.scale, 3)
        scratch = self._device_scratch if self.on_device else self._scratch
        estimate = None if self.history.taau is None else scratch.get("estimate", shape)
        base = self.history(colour, motion, tuple(frame.jitter), frame.motion_depth, rotation, frame.pixels_per_voxel,
                            slabs=frame.slabs, background=background, out=estimate)
        if self._device_filter is not None:  # on the device: the caller copies it back
            return self._stretched(self._device_filter.filter(base, clip_output=True))
        if base is None:  # not TAAU-based: the filter sharpens the bilinear upscale
            base = upscale_bilinear(colour, self.config.scale)
        # where the estimate is known to be the background colour, the filter makes one colour too: it runs inside
        window = None if self.history.taau is None else self.history.taau.background_window()
        if self.stretch == 2:  # the filter's bands double their rows as they make them: no filtered image in between
            return filter_image(base, *self.base_filter, scratch=self._scratch, clip_output=True, stretch=2,
                                stretch_a=STRETCH_CUBIC_A, window=window)
        return self._stretched(filter_image(base, *self.base_filter, scratch=self._scratch, clip_output=True,
                                            window=window))
