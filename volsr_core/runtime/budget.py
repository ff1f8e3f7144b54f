"""Frame-budget rendering: per frame, the finest level that fits a time budget; still frames refine.

As VTK's AutoAdjustSampleDistances picks its sample distance from the last frame times, a
:class:`BudgetRenderer` keeps a running estimate of each level's ms per frame (the median of its last
:data:`ESTIMATE_WINDOW` frames, so that one slow frame, a pause of the host or of another process, does not
move it: a level left is not timed again until it draws) and renders every moving frame with the finest level
whose estimate fits ``budget_ms``. The levels, finest first
(:func:`levels`): native full size, then by the size of the rendered frame, from 1/2 down: at a
scale the shipped models (largest variant first; at 4x following the view as the hosts do, ``stretch="auto"``),
TAAU alone, then the reduced-size render stretched bilinearly (what VTK's ImageSampleDistance gives; also at
1/2.5, 1/3, 1/5 and 1/6, between the scales, as VTK's distance is continuous); each with its own history (a
:class:`~volsr_core.runtime.pipeline.Pipeline`, or a :class:`MethodLevel`). The order is measured
(docs/performance.md): at a size a model beats the TAAU it refines and TAAU the bilinear upscale, and fewer
rendered pixels lose whatever follows (TAAU 2x beats the 4x models by 3.6-5.2 dB at 512²).

A model whose network costs more than :data:`~volsr_core.runtime.models.PAYING_NETWORK_SHARE` of
its LR render, as measured when the levels are timed, is left out (:func:`unpaid`): the same time
spent rendering buys more, and at 1024² on a CPU the U-Net models were also below VolSR XS at their
own scale.

While the camera holds still, frames refine progressively instead: every frame adds one more
Halton-jittered full-size sample per pixel (ray starts jittered per sample) to a running mean,
which after N frames *is* the native N-spp image (:func:`~volsr_core.temporal.supersample.
render_supersampled`'s box filter). Such a frame costs one native render whatever the budget, as
VTK's still render does; the next move returns to the budget.
"""
from __future__ import annotations

import statistics
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from volsr_core.render.raycaster import RayCaster
from volsr_core.runtime.methods import ReducedSize, Taau, VolSR
from volsr_core.runtime.models import PAYING_NETWORK_SHARE
from volsr_core.runtime.pipeline import KeepsLastFrame, Pipeline
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.sr.network_config import VARIANTS
from volsr_core.temporal.jitter import halton_jitter

VARIANT_ORDER = tuple(reversed(VARIANTS))  # larger first: better at the same scale
BILINEAR_FACTORS = (2, 2.5, 3, 4, 5, 6, 8)  # reduced sizes drawn bilinearly: volsr bench's --factors and the gaps
CALIBRATION_FRAMES = 3  # timed frames per level before the first frame (one frame alone was off by up to 25% here)
ESTIMATE_WINDOW = 5  # a level's estimate: the median of its last this many frame times (the calibration's first)
STILL_SEED = 10**6  # ray-start seeds of still samples, apart from the moving frames' (which count frames)


@dataclass(frozen=True)
class Level:
    """One way to make a frame: ``scale`` 1 (native full size); a shipped model's scale and ``variant``;
    TAAU alone at ``scale`` (``variant`` None); or, ``bilinear``, a render at 1/``scale`` size stretched
    bilinearly."""

    scale: float  # whole but for bilinear levels
    variant: str | None = None
    bilinear: bool = False

    @property
    def label(self) -> str:
        if self.scale == 1:
            return "native 1 spp"
        if self.bilinear:
            return f"native 1/{self.scale:g} size + bilinear"
        return f"TAAU {self.scale}x" if self.variant is None else f"VolSR {self.variant} {self.scale}x"


def levels(shipped: Sequence[dict[str, Any]], factors: Sequence[float] = BILINEAR_FACTORS) -> list[Level]:
    """Native full size, then by scale (smallest first): the shipped models (registry entries) of that
    scale, larger variant first, TAAU at that scale, and the 1/scale-size render + bilinear (``factors``)."""
    models = [Level(int(e["scale"]), e["variant"]) for e in shipped]
    taau = [Level(scale) for scale in {lv.scale for lv in models}]
    reduced = [Level(f, bilinear=True) for f in factors if f > 1]

    def finest_first(level: Level) -> tuple:
        rank = VARIANT_ORDER.index(level.variant) if level.variant in VARIANT_ORDER else len(VARIANT_ORDER)
        return level.scale, level.bilinear, level.variant is None, rank

    return [Level(1)] + sorted(models + taau + reduced, key=finest_first)


def unpaid(estimates: dict[Level, float]) -> dict[Level, str]:
    """The model levels whose network, their ms beyond TAAU's at the same scale, costs more than
    :data:`PAYING_NETWORK_SHARE` of the LR render (the 1/scale-size + bilinear level's ms), with why;
    a model without both of those levels among ``estimates`` is kept."""
    left_out = {}
    for level, ms in estimates.items():
        taau, render = estimates.get(Level(level.scale)), estimates.get(Level(level.scale, bilinear=True))
        if level.variant is None or taau is None or render is None:
            continue
        network = ms - taau
        if network > PAYING_NETWORK_SHARE * render:
            left_out[level] = (f"network {network:.0f} ms, more than {PAYING_NETWORK_SHARE:g} of the {render:.0f} ms "
                               "LR render")
    return left_out


def drawn_label(level: Level, pipeline: Any) -> str:
    """What a frame of ``level`` was: its label, or for a model level whose pipeline stretched its image
    (``Pipeline(stretch="auto")``) the model that ran and the stretch: 'VolSR XS 2x + bicubic 2x'."""
    if getattr(pipeline, "stretch", 1) == 1:
        return level.label
    return VolSR(pipeline, level.variant).label


class MethodLevel(KeepsLastFrame):
    """TAAU alone or a reduced-size render + bilinear (a :mod:`~volsr_core.runtime.methods` method on the
    renderer's caster), with the part of the :class:`~volsr_core.runtime.pipeline.Pipeline` interface the
    budget renderer uses."""

    def __init__(self, method: Taau | ReducedSize):
        self.method = method
        self.low_resolution_size = method.low_resolution_size
        self.last_timings: dict[str, float] = {}

    def reset(self, reason: str = "") -> None:
        self.method.reset()

    def render(self, camera: Camera) -> np.ndarray:
        frame = self.method(camera)
        self.last_timings = {"render_ms": frame.ms_render, "network_ms": frame.ms_upscale, "total_ms": frame.ms_total,
                             "readback_ms": frame.ms_readback}
        self.last_frame = frame.low_resolution
        return frame.image


@dataclass
class BudgetState:
    """What the last frame did: its level ("still" while refining), ms, and still samples accumulated."""

    level: str = ""
    ms: float = 0.0
    still_samples: int = 0
    ms_estimates: dict[str, float] = field(default_factory=dict)


class BudgetRenderer(KeepsLastFrame):
    """Renders ``volume`` at ``size`` within ``budget_ms`` per moving frame (see the module docstring); the
    ``budget_ms`` attribute may change between frames (a host's slider), the estimates kept.

    - ``choices``: the :class:`Level` list to choose from, finest first (default :func:`levels` of the
      shipped models, less the TAAU levels whose scale does not divide ``size``); ``model_files`` maps
      a model level to its model file (default: the shipped one, which at an even scale of 4 or more follows the view
      as in the hosts, ``Pipeline(stretch="auto")``: the model of half the scale at half the size, stretched
      bicubically, where a voxel spans two output pixels or more or the view turns fast; the frame's ``state.level``
      then names it, e.g. 'VolSR XS 2x + bicubic 2x'). The model levels :func:`unpaid` finds
      when the levels are timed are then dropped from ``choices``; ``left_out`` says why, ``timed`` holds the
      timings it judged (each level's median ms on the first camera);
    - ``window``: a level's ms estimate is the median of its last ``window`` frame times, the
      ``CALIBRATION_FRAMES`` timed first among them (one slow frame moves it by nothing);
    - ``finer_margin``: a finer level is taken only when its estimate is below this fraction of the
      budget (hysteresis: levels do not alternate frame by frame, which would drop the history);
    - ``device``, ``threads``, ``sample_distance``, ``background``: as :class:`Pipeline` takes them.

    Every level is timed on the first camera before the first frame (a warm-up frame, in which kernels
    compile and sessions warm up, then ``CALIBRATION_FRAMES`` timed ones), which seed the
    estimates. ``render(camera)`` returns float32 (H, W, 3) in [0, 1]; ``state`` says what the frame
    was. Like a :class:`Pipeline` it has ``size``, ``scale`` and
    ``low_resolution_size`` (the level drawn last; 1 and ``size`` while still), ``caster``,
    ``last_timings``, ``last_frame`` and ``last_low_resolution`` (the LR frame as rendered and in host memory, copied
    when read; None after a native or reduced-size level, which render the colour alone), so the batch and the
    comparison methods take it.
    """

    def __init__(self, volume: Volume, transfer_function: TransferFunction, budget_ms: float, *,
                 size: tuple[int, int] = (512, 512), choices: Sequence[Level] | None = None,
                 model_files: dict[Level, Any] | None = None, window: int = ESTIMATE_WINDOW, finer_margin: float = 0.9,
                 device: str = "cpu", threads: int | None = None, sample_distance: float | None = None,
                 background: tuple[float, float, float] = (0.0, 0.0, 0.0)):
        if not budget_ms > 0:
            raise ValueError(f"budget_ms must be positive, got {budget_ms}")
        from volsr_core.runtime.models import shipped_models

        self.budget_ms, self.size = float(budget_ms), (int(size[0]), int(size[1]))
        if window < 1:
            raise ValueError(f"window must be at least 1 frame, got {window}")
        self.finer_margin = float(finer_margin)
        if choices is None:
            choices = [lv for lv in levels(shipped_models()) if lv.variant is not None or lv.bilinear
                       or (self.size[0] % lv.scale == 0 and self.size[1] % lv.scale == 0)]
        self.choices = list(choices)
        files = dict(model_files or {})
        self.caster = RayCaster(volume, transfer_function, sample_distance=sample_distance, device=device,
                                background=background, start_jitter="ign")
        self.pipelines: dict[Level, Pipeline | MethodLevel] = {}
        for level in self.choices:
            if level.bilinear:
                self.pipelines[level] = MethodLevel(ReducedSize(self.caster, self.size, level.scale))
            elif level.scale > 1 and level.variant is None:
                if self.size[0] % level.scale or self.size[1] % level.scale:
                    raise ValueError(f"TAAU {level.scale}x needs a size divisible by {level.scale}, got {self.size}")
                self.pipelines[level] = MethodLevel(Taau(self.caster, self.size, level.scale))
            elif level.scale > 1:
                # a shipped model follows the view as the hosts' does (stretch "auto": at 4x the 2x model at half
                # the size, stretched, where a voxel spans two output pixels or more or the view turns fast); a given
                # file runs as it is
                model = files.get(level)
                self.pipelines[level] = Pipeline(volume, transfer_function, model, scale=level.scale, size=self.size,
                                                 variant=level.variant, device=device, threads=threads,
                                                 sample_distance=sample_distance, background=background,
                                                 stretch="auto" if model is None else 1)
        self.estimates: dict[Level, float] = {}
        self._recent: dict[Level, deque[float]] = {level: deque(maxlen=int(window)) for level in self.choices}
        self.left_out: dict[str, str] = {}
        self.timed: dict[Level, float] = {}
        self.current: Level | None = None
        self.state = BudgetState()
        self.last_timings: dict[str, float] = {}
        self._last_camera: Camera | None = None
        self._still_sum: np.ndarray | None = None
        self._still_count = 0

    @property
    def scale(self) -> int:
        """The scale of the level drawn last (1 before the first frame and while still)."""
        return 1 if self.current is None or self.state.level == "still" else self.current.scale

    @property
    def low_resolution_size(self) -> tuple[int, int]:
        if self.scale == 1:
            return self.size
        return self.pipelines[self.current].low_resolution_size

    # timing ----------------------------------------------------------------------------------------
    def _calibrate(self, camera: Camera) -> None:
        """One untimed frame of every level on ``camera``, then ``CALIBRATION_FRAMES`` timed ones, which
        seed its estimate; their histories are then dropped, and so are the levels :func:`unpaid` names."""
        for level in self.choices:
            self._render_level(level, camera)
            times = []
            for _ in range(CALIBRATION_FRAMES):
                started = time.perf_counter()
                self._render_level(level, camera)
                times.append(1000.0 * (time.perf_counter() - started))
            self.timed[level] = statistics.median(times)
            for ms in times:
                self._record(level, ms)
            if level in self.pipelines:
                self.pipelines[level].reset("calibrated")
        for level, why in unpaid(self.timed).items():
            self.choices.remove(level)
            del self.pipelines[level]  # its estimate stays, for the record
            self.left_out[level.label] = why

    def _record(self, level: Level, ms: float) -> None:
        """``ms`` the latest frame time of ``level``; its estimate, the median of the last ``window``."""
        self._recent[level].append(ms)
        self.estimates[level] = statistics.median(self._recent[level])

    def choose(self) -> Level:
        """The finest level whose estimate fits the budget (a finer one than the current only with margin);
        the coarsest when none does."""
        for level in self.choices:
            limit = self.budget_ms
            if self.current is not None and self.choices.index(level) < self.choices.index(self.current):
                limit *= self.finer_margin
            if self.estimates[level] <= limit:
                return level
        return self.choices[-1]

    # rendering -------------------------------------------------------------------------------------
    def _render_level(self, level: Level, camera: Camera) -> np.ndarray:
        if level.scale == 1:
            return self.caster.render_color(camera, *self.size)
        return self.pipelines[level].render(camera)

    def _is_still(self, camera: Camera) -> bool:
        last = self._last_camera
        return last is not None and camera.to_dict() == last.to_dict()

    def _refine(self, camera: Camera) -> np.ndarray:
        """One more jittered full-size sample per pixel into the running mean: after N still frames the
        native N-spp image (the Halton offsets and ray-start seeds of ``render_supersampled(..., seed=STILL_SEED)``)."""
        k = self._still_count
        colour = self.caster.render_color(camera, *self.size, jitter=halton_jitter(k, 1 << 16),
                                          seed=STILL_SEED + k).astype(np.float64)
        self._still_sum = colour if self._still_sum is None else self._still_sum + colour
        self._still_count = k + 1
        return (self._still_sum / self._still_count).astype(np.float32)

    def render(self, camera: Camera) -> np.ndarray:
        """The frame for ``camera``: float32 (H, W, 3) in [0, 1], H, W = ``size``."""
        if not self.estimates:
            self._calibrate(camera)
        started = time.perf_counter()
        if self._is_still(camera):
            image, label = self._refine(camera), "still"
        else:
            self._still_sum, self._still_count = None, 0
            level = self.choose()
            if level != self.current and level in self.pipelines:
                self.pipelines[level].reset("level changed")
            self.current = level
            image, label = self._render_level(level, camera), drawn_label(level, self.pipelines.get(level))
        ms = 1000.0 * (time.perf_counter() - started)
        pipeline = self.pipelines.get(self.current) if label != "still" else None
        if pipeline is not None:
            self.last_timings, self.last_frame = dict(pipeline.last_timings), pipeline.last_frame
        else:
            self.last_timings, self.last_frame = {"render_ms": ms, "network_ms": 0.0, "total_ms": ms}, None
        if label != "still":
            self._record(self.current, ms)
        self._last_camera = camera
        self.state = BudgetState(label, ms, self._still_count,
                                 {level.label: round(v, 2) for level, v in self.estimates.items()})
        return image
