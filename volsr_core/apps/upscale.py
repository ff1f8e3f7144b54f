"""Batch render-and-upscale (``volsr upscale``): a camera path through a Pipeline to PNG frames and an MP4.

- :func:`upscale_cameras` renders every camera with a :class:`~volsr_core.runtime.pipeline.Pipeline`
  and writes ``frame_NNNN.png`` (and optionally one MP4), either the upscaled image or, with
  ``side_by_side``, three labelled panels (:mod:`volsr_core.runtime.methods`): a native full-size
  1-spp render, a native render at 1/scale size upscaled bilinearly (what VTK's
  ``ImageSampleDistance`` does) and VolSR;
- with ``reference_spp`` it also measures PSNR against an N-spp native render of every frame;
- :func:`auto_variant` picks the largest shipped variant whose network costs at most
  :data:`~volsr_core.runtime.models.PAYING_NETWORK_SHARE` of an LR render (:func:`choose_variant`
  is the rule), at the whole scale or, stretched, at a part of it.

Every PNG and MP4 is written atomically (a temporary name in the same folder, then a rename), so
an interrupted run leaves complete files or none; the next run into the same folder deletes what a
killed one left (its temporary files) and the frames of the run before it (:func:`clear_previous_run`),
so a frame folder never mixes runs.
"""
from __future__ import annotations

import contextlib
import os
import re
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from volsr_core.atomic import stale_parts
from volsr_core.images import mp4_writer, side_by_side, to_uint8, write_png
from volsr_core.runtime.methods import Method, Native, ReducedSize, VolSR
from volsr_core.runtime.models import PAYING_NETWORK_SHARE
from volsr_core.sr.network_config import VARIANTS

VARIANTS_LARGEST_FIRST = tuple(reversed(VARIANTS))
PANELS = ("native 1 spp", "bilinear", "VolSR")


# -- inputs -----------------------------------------------------------------------------------------
VOLUME_SUFFIXES = (".nii.gz", ".nii", ".nrrd", ".nhdr", ".mha", ".mhd", ".vti", ".dcm")


@dataclass
class BatchInput:
    """One volume of a batch: its output name, its path (None: the built-in phantom), or why it cannot be read."""

    name: str
    source: str | None
    error: str | None = None


def input_name(source: str | None) -> str:
    """The name of an input's outputs: the file or folder name without a volume suffix; 'phantom' for None."""
    if source is None:
        return "phantom"
    name = Path(os.path.normpath(source)).name
    for suffix in VOLUME_SUFFIXES:
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name or "volume"


def expand_inputs(items: Sequence[str]) -> list[BatchInput]:
    """The volumes that INPUT arguments name, with unique output names.

    A ``.txt`` file lists volumes one per line (blank lines and ``#`` comments skipped; relative
    paths are taken from the list's folder). No items: the phantom. A list that cannot be read
    becomes one input that fails with the reason.
    """
    sources: list[tuple[str | None, str | None]] = []
    for item in items or [None]:
        if item is not None and item.lower().endswith(".txt"):
            try:
                lines = Path(item).read_text(encoding="utf-8").splitlines()
            except FileNotFoundError:
                sources.append((item, "no such file"))
                continue
            except (OSError, UnicodeDecodeError) as err:
                sources.append((item, f"cannot read the list ({getattr(err, 'strerror', None) or err})"))
                continue
            folder = Path(item).parent
            listed = [line.strip() for line in lines]
            listed = [line for line in listed if line and not line.startswith("#")]
            if not listed:
                sources.append((item, "the list names no volume"))
            sources += [(str(folder / line) if not os.path.isabs(line) else line, None) for line in listed]
        else:
            sources.append((item, None))
    inputs, taken = [], set()
    for source, error in sources:
        base = input_name(source)
        name, k = base, 2
        while name in taken:
            name, k = f"{base}_{k}", k + 1
        taken.add(name)
        inputs.append(BatchInput(name, source, error))
    return inputs


def video_paths(video: str | os.PathLike | None, names: Sequence[str]) -> dict[str, Path]:
    """Where each input's MP4 goes: ``video`` itself for one input and an ``.mp4`` name; otherwise
    ``<name>.mp4`` in ``video``'s folder (an ``.mp4`` name) or in ``video`` (a folder)."""
    if video is None:
        return {}
    video = Path(video)
    if video.suffix.lower() == ".mp4":
        if len(names) == 1:
            return {names[0]: video}
        return {name: video.parent / f"{name}.mp4" for name in names}
    return {name: video / f"{name}.mp4" for name in names}


# -- the --variant auto rule ------------------------------------------------------------------------
def choose_variant(network_ms: Mapping[Any, float], budget_ms: float) -> Any:
    """The first candidate of ``network_ms`` (candidate -> ms per frame, in the order they are preferred: the larger
    variant first) whose network time per frame is at most ``budget_ms``; when none is, the fastest."""
    return next((c for c, ms in network_ms.items() if ms <= budget_ms), min(network_ms, key=network_ms.get))


def network_ms(engine, low_resolution_size: tuple[int, int], repeats: int = 3) -> float:
    """The engine's time for one frame, ms: one warm-up run, then the median of ``repeats`` runs on zeros."""
    config = engine.config
    w, h = low_resolution_size
    frames = config.previous_frames + 1
    lr = np.zeros((1, frames, config.in_channels, h, w), np.float32)
    motion = np.zeros((1, frames, 2, h, w), np.float32)
    jitter = np.zeros((1, frames, 2), np.float32)
    history = (np.zeros((1, config.history_channels, h * config.scale, w * config.scale), np.float32)
               if config.takes_history else None)
    engine(lr, motion, jitter, history)
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        engine(lr, motion, jitter, history)
        times.append(1000 * (time.perf_counter() - started))
    return statistics.median(times)


def render_ms(caster, camera, size: tuple[int, int]) -> float:
    """ms of one 1-spp render of ``camera`` at ``size`` (after a small warm-up render that compiles the kernels)."""
    caster.render(camera, 16, 16)
    started = time.perf_counter()
    caster.render(camera, size[0], size[1])
    return 1000 * (time.perf_counter() - started)


def auto_variant(caster, camera, size: tuple[int, int], scale: int, *, device: str = "cpu",
                 stretches: Sequence[int] | None = None, log: Callable[[str], None] = print) -> tuple[str, Path, int]:
    """The shipped variant ``--variant auto`` takes, its model file and the stretch after it.

    ``scale`` is the whole factor from the LR frame to ``size``. Budget:
    :data:`~volsr_core.runtime.models.PAYING_NETWORK_SHARE` of one LR render (``size / scale``, 1 spp) of ``camera``.
    The candidates are the shipped models at ``scale`` / k for k = 1, 2, 4, ... (``stretches``: only those k; k
    divides ``scale``, the model's image stretched by k bicubically, as ``Pipeline(stretch=k)`` does), the model of
    the whole scale first, each scale's variants largest first; they are timed in that order (:func:`network_ms` on an
    LR frame; the stretch not counted) until one fits, else the fastest (:func:`choose_variant`). So at 8x, where the
    one 8x model is a U-Net, a CPU takes XS 4x stretched 2x, as ``volsr upscale --scale 8`` does by default.
    """
    from volsr_core.runtime.engines import open_engine
    from volsr_core.runtime.models import find_model, model_file_to_run, shipped_models
    from volsr_core.runtime.pipeline import stretch_steps

    shipped = {(e["variant"], e["scale"]) for e in shipped_models()}
    stretches = stretches or stretch_steps(scale)
    candidates = [(v, k) for k in stretches for v in VARIANTS_LARGEST_FIRST if (v, scale // k) in shipped]
    if not candidates:
        find_model("S", scale // stretches[0])  # raises the one-line error naming what is shipped
    lr_size = (-(-size[0] // scale), -(-size[1] // scale))
    lr_ms = render_ms(caster, camera, lr_size)
    budget = PAYING_NETWORK_SHARE * lr_ms
    measured: dict[tuple[str, int], float] = {}
    for variant, k in candidates:
        engine = open_engine(model_file_to_run(variant, scale // k, device), device=device)
        measured[variant, k] = network_ms(engine, lr_size)
        if measured[variant, k] <= budget:
            break
    variant, k = choose_variant(measured, budget)

    def named(v: str, stretch: int) -> str:
        return f"{v} {scale // stretch}x" + (f" stretched {stretch}x" if stretch > 1 else "")

    times = ", ".join(f"{named(v, s)} {ms:.0f} ms" for (v, s), ms in measured.items())
    log(f"variant auto: network per {size[0]}x{size[1]} frame {times}; budget {budget:.0f} ms "
        f"({PAYING_NETWORK_SHARE:g} of the {lr_size[0]}x{lr_size[1]} LR render, {lr_ms:.0f} ms) -> {named(variant, k)}")
    return variant, model_file_to_run(variant, scale // k, device), k


# -- one input --------------------------------------------------------------------------------------
@dataclass
class InputSummary:
    """What one input of a batch produced: timings per frame, PSNR per frame, files, or the error."""

    name: str
    source: str
    frames: int = 0
    size: tuple[int, int] = (0, 0)
    low_resolution_size: tuple[int, int] = (0, 0)
    slabs: int = 0  # depth slabs each LR frame was rendered in (the layered TAAU's), 0: none
    stretch: int = 1  # the bicubic stretch after the model (Pipeline's stretch), 1: none
    timings: dict[str, list[float]] = field(default_factory=lambda: {"render_ms": [], "network_ms": [],
                                                                     "total_ms": [], "readback_ms": []})
    method_ms: dict[str, list[float]] = field(default_factory=dict)  # method -> total ms per frame
    psnr: dict[str, list[float]] = field(default_factory=dict)   # method -> dB per frame
    reference_spp: int = 0
    levels: dict[str, int] = field(default_factory=dict)  # frame-budget mode: frames made by each level
    models: dict[str, int] = field(default_factory=dict)  # stretch "auto": frames made by each model it ran
    left_out: dict[str, str] = field(default_factory=dict)  # frame-budget mode: levels dropped, and why
    outputs: list[Path] = field(default_factory=list)
    error: str | None = None

    def ms(self, stage: str) -> float:
        """Median ms per frame of ``stage`` (render_ms, network_ms, total_ms, readback_ms); the first frame's
        one-off costs (kernel compilation, session warm-up) do not move a median."""
        values = self.timings[stage]
        return statistics.median(values) if values else float("nan")

    def method_line(self, method: str) -> str:
        """``method``'s median ms per frame and, when measured, its mean PSNR: "VolSR 41.9 ms, 31.41 dB"."""
        text = f"{method} {statistics.median(self.method_ms[method]):.1f} ms"
        return text + (f", {np.mean(self.psnr[method]):.2f} dB" if method in self.psnr else "")

    def levels_text(self) -> str:
        """Frame-budget mode's levels in the order first used, with their frames: "VolSR XS 2x 12, TAAU 2x 4"."""
        return ", ".join(f"{level} {count}" for level, count in self.levels.items())

    def models_text(self) -> str:
        """Stretch "auto"'s models in the order first used, with their frames: "volsr-XS-4x.onnx in 2 depth slabs 9,
        volsr-XS-2x.onnx stretched 2x 15"."""
        return ", ".join(f"{model} {count}" for model, count in self.models.items())

    def left_out_text(self) -> str:
        """Frame-budget mode's dropped levels: "VolSR S 2x (network 105 ms, more than ...)"."""
        return ", ".join(f"{level} ({why})" for level, why in self.left_out.items())

    def line(self) -> str:
        if self.error is not None:
            done = f" after {self.frames} frame(s)" if self.frames else ""
            return f"{self.name}: FAILED{done}: {self.error}"
        (w, h), (lw, lh) = self.size, self.low_resolution_size
        source = "" if self.levels else f" from {lw}x{lh}"  # frame-budget mode: the levels' sizes vary
        if len(self.models) < 2:  # one model made every frame (several: stretch "auto" says per model below)
            source += f" in {self.slabs} depth slabs" if self.slabs else ""
            source += f", the model's image stretched {self.stretch}x" if self.stretch > 1 else ""
        text = (f"{self.name}: {self.frames} frames of {w}x{h}{source}; VolSR ms per frame (median): "
                f"LR render {self.ms('render_ms'):.1f}, network {self.ms('network_ms'):.1f}, "
                f"total {self.ms('total_ms'):.1f}")
        if self.ms("readback_ms") > 0:  # a frame made on the GPU
            text += f" (then copied from the GPU in {self.ms('readback_ms'):.1f})"
        if len(self.method_ms) > 1 or self.psnr:
            text += (f"; per method (median ms, mean PSNR vs {self.reference_spp}-spp native)" if self.psnr
                     else "; per method (median ms)")
            text += ": " + " | ".join(self.method_line(m) for m in self.method_ms)
        if self.levels:
            text += f"; frames per level: {self.levels_text()}"
        if len(self.models) > 1:
            text += f"; frames per model (--stretch auto): {self.models_text()}"
        if self.left_out:
            text += f"; left out: {self.left_out_text()}"
        if self.outputs:
            text += f"; wrote {self.outputs[0].parent}/" + "".join(f", {p}" for p in self.outputs if p.suffix == ".mp4")
        return text


def summary_markdown(summaries: Sequence[InputSummary], scale: str, model: str, budget_ms: float | None = None) -> str:
    """OUT/summary.md: per input and method, median ms per frame, its ratio to the native 1-spp render's
    and mean PSNR, so the trade between time and quality reads at a glance; in frame-budget mode
    (``budget_ms``) also the frames each level made. ``scale`` as the title says it: "2x", "4x (2x + bicubic 2x)"."""
    title = f"a {budget_ms:g} ms frame budget" if budget_ms is not None else f"{scale} with {model}"
    lines = [f"# volsr upscale: {title}", "",
             "| input | frames | size | method | ms per frame (median) | time / native 1 spp | PSNR dB (mean) |",
             "|---|---:|---|---|---:|---:|---:|"]
    for s in summaries:
        if s.error is not None:
            lines.append(f"| {s.name} | {s.frames} | | FAILED: {s.error} | | | |")
            continue
        native = s.method_ms.get("native 1 spp")
        for method, values in s.method_ms.items():
            ms = statistics.median(values)
            ratio = f"{ms / statistics.median(native):.2f}" if native else "-"
            psnr = f"{np.mean(s.psnr[method]):.2f}" if method in s.psnr else "-"
            size = f"{s.size[0]}x{s.size[1]}"
            lines.append(f"| {s.name} | {s.frames} | {size} | {method} | {ms:.1f} | {ratio} | {psnr} |")
    reference = next((s.reference_spp for s in summaries if s.reference_spp), 0)
    if reference:
        lines += ["", f"PSNR against the native render of every frame with {reference} samples per pixel."]
    if any(s.levels for s in summaries):
        lines += ["", "Frames per level (VolSR is what the budget chose for each frame; \"still\": refining a "
                  "still camera):"]
        lines += [f"- {s.name}: {s.levels_text()}" + (f"; left out: {s.left_out_text()}" if s.left_out else "")
                  for s in summaries if s.levels]
    if any(len(s.models) > 1 for s in summaries):
        lines += ["", "Frames per model (`--stretch auto`: the half-size model stretched where the view samples the "
                  "volume finely or turns fast):"]
        lines += [f"- {s.name}: {s.models_text()}" for s in summaries if len(s.models) > 1]
    return "\n".join(lines) + "\n"


def model_label(pipeline) -> str:
    """The model a pipeline ran for its last frame, as the summary names it: "volsr-XS-4x.onnx in 2 depth slabs",
    "volsr-XS-2x.onnx stretched 2x"."""
    path = getattr(pipeline.engine, "path", None)
    text = path.name if path is not None else f"the {pipeline.model_scale}x model"
    text += f" in {pipeline.slabs} depth slabs" if pipeline.slabs else ""
    return text + (f" stretched {pipeline.stretch}x" if pipeline.stretch > 1 else "")


FRAME_NAME = re.compile(r"frame_\d{4,}\.png")


def clear_previous_run(out_dir: Path, video: Path | None = None) -> list[Path]:
    """Delete what an earlier run left where this one writes: the ``frame_NNNN.png`` files in ``out_dir``
    (other files stay), and the temporary files of frames and of ``video`` that a killed run left. Returns
    what was deleted."""
    old = [p for p in out_dir.glob("frame_*.png") if FRAME_NAME.fullmatch(p.name)] if out_dir.is_dir() else []
    old += stale_parts(out_dir / "frame_*.png") + (stale_parts(video) if video is not None else [])
    for path in old:
        path.unlink(missing_ok=True)
    return old


def upscale_cameras(pipeline, cameras: Sequence, out_dir: str | os.PathLike, *, video: str | os.PathLike | None = None,
                    fps: float = 24.0, side_by_side_panels: bool = False, reference_spp: int = 0,
                    summary: InputSummary | None = None, progress: bool = True,
                    on_frame: Callable[[int], None] | None = None, bilinear_scale: int | None = None) -> InputSummary:
    """Render every camera through ``pipeline`` (a :class:`~volsr_core.runtime.pipeline.Pipeline` or a
    :class:`~volsr_core.runtime.budget.BudgetRenderer`) to ``out_dir/frame_NNNN.png`` (and ``video``, an MP4).

    ``side_by_side_panels``: each frame shows native 1 spp | bilinear (from 1/``bilinear_scale`` size,
    default the pipeline's scale) | VolSR, labelled.
    ``reference_spp`` > 0: PSNR (skimage) of VolSR and bilinear (and native 1 spp when rendered)
    against an N-spp native render of the same camera. ``on_frame(i)`` runs after frame i is
    written (a progress hook; an exception from it stops the run like any other, and the MP4 is
    then not written). Frames of an earlier run in ``out_dir`` are deleted first
    (:func:`clear_previous_run`). Fills and returns ``summary``.
    """
    from tqdm import tqdm

    from volsr_core.temporal.supersample import render_supersampled

    if reference_spp:
        from skimage.metrics import peak_signal_noise_ratio
    out_dir = Path(out_dir)
    clear_previous_run(out_dir, None if video is None else Path(video))
    out_dir.mkdir(parents=True, exist_ok=True)
    if video is not None:
        Path(video).parent.mkdir(parents=True, exist_ok=True)
    summary = summary or InputSummary(out_dir.name, "")
    summary.size, summary.low_resolution_size = pipeline.size, pipeline.low_resolution_size
    summary.slabs = getattr(pipeline, "slabs", 0)  # a frame-budget renderer has none of its own
    summary.reference_spp = int(reference_spp)
    width, height = pipeline.size
    caster = pipeline.caster  # the same volume, transfer function, step and background as the LR frames
    methods: dict[str, Method] = {"VolSR": VolSR(pipeline)}
    if side_by_side_panels or reference_spp:
        methods["bilinear"] = ReducedSize(caster, pipeline.size, bilinear_scale or pipeline.scale, "bilinear")
    if side_by_side_panels:
        methods["native 1 spp"] = Native(caster, pipeline.size, 1)
    with contextlib.ExitStack() as stack:
        mp4 = stack.enter_context(mp4_writer(video, fps)) if video is not None else None
        bar = stack.enter_context(tqdm(total=len(cameras), desc=summary.name, unit="frame", disable=not progress,
                                       leave=False))
        for i, camera in enumerate(cameras):
            results = {}
            for name, method in methods.items():
                frame = method(camera)
                results[name] = frame.image
                summary.method_ms.setdefault(name, []).append(frame.ms_total)
            for stage, ms in pipeline.last_timings.items():
                summary.timings[stage].append(ms)
            state = getattr(pipeline, "state", None)  # a BudgetRenderer: the level that made the frame
            if state is not None:
                summary.levels[state.level] = summary.levels.get(state.level, 0) + 1
                summary.left_out = dict(pipeline.left_out)
            if reference_spp:
                reference = render_supersampled(caster, camera, width, height, spp=reference_spp)
                for name in ("VolSR", "bilinear", "native 1 spp"):
                    if name in results:
                        score = peak_signal_noise_ratio(reference, np.clip(results[name], 0, 1).astype(np.float32),
                                                        data_range=1.0)
                        summary.psnr.setdefault(name, []).append(float(score))
            if side_by_side_panels:
                frame = side_by_side([(label, results[label]) for label in PANELS])
            else:
                frame = to_uint8(results["VolSR"])
            png = out_dir / f"frame_{i:04d}.png"
            write_png(png, frame)
            summary.outputs.append(png)
            if mp4 is not None:
                mp4.append_data(frame)
            summary.frames = i + 1
            summary.slabs = getattr(pipeline, "slabs", 0)  # the last frame's ("auto" stretch chooses its model)
            summary.stretch = getattr(pipeline, "stretch", 1)
            if getattr(pipeline, "auto_stretch", False):
                model = model_label(pipeline)
                summary.models[model] = summary.models.get(model, 0) + 1
            bar.update(1)
            if on_frame is not None:
                on_frame(i)
    if video is not None:
        summary.outputs.append(Path(video))
    return summary
