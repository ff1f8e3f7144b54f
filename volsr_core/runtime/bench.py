"""Quality against time: native rendering, native + bilinear, TAAU and VolSR side by side.

For each scene (a volume and its placed transfer function) the camera orbits ``frames`` frames of
``degrees`` each (so temporal methods have history). Every method renders every frame, in one
run, interleaved frame by frame (the order rotating per frame, so machine noise hits all alike):

- ``native``: full size, ``spp`` jittered samples per pixel (1 = the pixel centres);
- ``bilinear``: full size / ``factor`` (VTK's ImageSampleDistance), bilinearly upscaled;
- ``taau``: full size / ``scale``, Halton-jittered, motion vectors, :class:`TemporalUpsampler`;
- ``volsr``: :class:`~volsr_core.runtime.pipeline.Pipeline` for every model (variant, scale).

Each is compared with a supersampled native ground truth (``reference_spp`` Halton samples per
pixel, :func:`render_supersampled`) by PSNR and SSIM (scikit-image). Quality is averaged over the
frames after ``warmup`` warm-up frames; times are medians over the same frames (the warm-up also
absorbs kernel compilation). ``ms_render`` is the ray casting, ``ms_network`` what follows it (the
network for VolSR, the bilinear or TAAU upscaling for those, 0 for native), ``ms_total`` their sum.

:func:`run_benchmark` runs it and :func:`write_outputs` writes bench.json, bench.md and bench.png;
:func:`check_targets` checks the issue's two targets (docs/performance.md). ``volsr bench`` is the
command-line wrapper.
"""
from __future__ import annotations

import json
import math
import os
import platform
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numba
import numpy as np

from volsr_core.atomic import atomic_write
from volsr_core.errors import InputError, VolSRError

SPP = (1, 2, 4)
FACTORS = (2, 3, 4, 6, 8)
SCALES = (2, 4, 8)
VARIANTS = ("S", "M", "L")
METHOD_ORDER = ("native", "bilinear", "taau", "volsr")
TARGET_SCALE = 4            # target 1: VolSR at 4x ...
TARGET_TIME_FRACTION = 1 / 3  # ... in at most this fraction of native 1-spp time


# -- scenes ---------------------------------------------------------------------------------------
@dataclass
class Scene:
    """A volume with its transfer function placed on its values; ``label`` names it in reports."""

    name: str
    volume: Any
    transfer_function: Any
    preset: str
    placement: str | tuple[float, float]

    @property
    def label(self) -> str:
        lo, hi = self.transfer_function.value_range
        how = f" ({self.placement})" if isinstance(self.placement, str) else ""
        return f"{self.name}, {self.preset} on {lo:.4g}..{hi:.4g}{how}"


def _is_placement(text: str) -> bool:
    if text in ("auto", "none"):
        return True
    try:
        parse_placement(text)
    except ValueError:
        return False
    return True


def parse_placement(text: str) -> str | tuple[float, float]:
    """'auto', 'none' or 'LO,HI' (LO < HI); ValueError otherwise."""
    if text in ("auto", "none"):
        return text
    parts = text.split(",")
    if len(parts) != 2:
        raise ValueError(f"range must be auto, none or LO,HI, got {text!r}")
    lo, hi = float(parts[0]), float(parts[1])
    if not hi > lo:
        raise ValueError(f"range needs LO < HI, got {text!r}")
    return lo, hi


def parse_scene_spec(spec: str | None) -> tuple[str | None, str | None, str | tuple[float, float] | None]:
    """``VOLUME[:PRESET[:RANGE]]`` -> (path or None for the phantom, preset or None, range or None).

    RANGE is ``auto``, ``none`` or ``LO,HI``; ``VOLUME:RANGE`` and ``VOLUME::RANGE`` keep the
    default preset. ``phantom`` (or nothing) is the built-in phantom. A spec that names an
    existing file or folder as a whole is taken as a path, colons and all.
    """
    if spec is None or spec == "":
        return None, None, None
    path, preset, placement = spec, None, None
    if not Path(spec).exists() and ":" in spec:
        head, _, last = spec.rpartition(":")
        if _is_placement(last):
            placement = parse_placement(last)
            before, sep, middle = head.rpartition(":")
            if sep and not Path(head).exists():
                path, preset = before, middle or None
            else:
                path = head
        else:
            path, preset = head, last or None
    if path == "" or (path == "phantom" and not Path(path).exists()):
        path = None
    return path, preset, placement


def load_scene(spec: str | None, preset: str | None = None, placement: str | tuple[float, float] = "auto") -> Scene:
    """The scene a spec names (:func:`parse_scene_spec`); ``preset``/``placement`` are the defaults
    for what the spec leaves out (preset: CT-Phantom for the phantom, CT-Bone otherwise)."""
    from volsr_core.io import make_phantom
    from volsr_core.scene import Volume
    from volsr_core.scene.presets import get_preset, place_on_volume

    path, own_preset, own_placement = parse_scene_spec(spec)
    if path is None:
        volume, name = Volume.from_record(make_phantom()), "phantom"
    else:
        volume, name = Volume.load(path), Path(path).name
    preset = own_preset or preset or ("CT-Phantom" if path is None else "CT-Bone")
    placement = own_placement if own_placement is not None else placement
    tf = place_on_volume(get_preset(preset), volume, placement)
    return Scene(name, volume, tf, tf.name or preset, placement)


def camera_path(volume, frames: int, degrees: float = 2.0, elevation: float = 0.0) -> list:
    """``frames`` cameras orbiting from the anterior view, ``degrees`` apart, clipping reset to the volume."""
    from volsr_core.scene import Camera
    from volsr_core.scene.camera_paths import orbit

    start = Camera.framing(volume.bounds)
    return [c.reset_clipping_range(volume.bounds) for c in orbit(start, frames, degrees=frames * degrees,
                                                                   elevation=elevation)]


# -- models ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ModelSpec:
    """An ONNX model file with the scale and variant its metadata says."""

    path: Path
    variant: str
    scale: int


def infer_variant(config) -> str | None:
    """'S', 'M' or 'L' when ``config`` (a NetworkConfig) is that variant's shape, else None."""
    from volsr_core.sr.network_config import variant_config

    for name in VARIANTS:
        try:
            reference = variant_config(name, config.scale, config.previous_frames, config.features,
                                       recurrent=config.recurrent, taau_base=config.taau_base)
        except ValueError:
            continue
        if (reference.fold, reference.widths, reference.reweight_width, reference.feature_width) == (
                config.fold, config.widths, config.reweight_width, config.feature_width):
            return name
    return None


def find_models(models_dir: str | os.PathLike | None = None, variants: Sequence[str] = VARIANTS,
                scales: Sequence[int] = SCALES) -> list[ModelSpec]:
    """The models to benchmark, by scale then variant.

    Without ``models_dir``: the shipped registry's (:func:`~volsr_core.runtime.models.shipped_models`,
    SHA-256 checked). With it: every ``*.onnx`` in the folder, scale and variant read from the
    model's metadata (:class:`OnnxEngine`); a model whose shape is no named variant goes by its file
    name and is kept whatever ``variants`` says. Only ``scales`` are kept.
    """
    wanted = {v.upper() for v in variants}
    found: list[ModelSpec] = []
    if models_dir is None:
        from volsr_core.runtime.models import model_file, shipped_models

        for entry in shipped_models():
            if entry["variant"] in wanted and entry["scale"] in scales and "onnx" in entry.get("files", {}):
                found.append(ModelSpec(model_file(entry["variant"], entry["scale"], "onnx"), entry["variant"],
                                       int(entry["scale"])))
    else:
        folder = Path(models_dir)
        if not folder.is_dir():
            raise InputError(folder, "is not a folder of .onnx models")
        paths = sorted(folder.glob("*.onnx"))
        if not paths:
            raise InputError(folder, "holds no .onnx models")
        _require("onnxruntime", "VolSR models run in onnxruntime: pip install 'volsr[onnx]'")
        from volsr_core.runtime.engines import OnnxEngine

        for path in paths:
            config = OnnxEngine(path, providers=["CPUExecutionProvider"]).config
            variant = infer_variant(config)
            if config.scale in scales and (variant is None or variant in wanted):
                found.append(ModelSpec(path, variant or path.stem, int(config.scale)))
    return sorted(found, key=lambda m: (m.scale, VARIANTS.index(m.variant) if m.variant in VARIANTS else 9,
                                        str(m.path)))


def _require(module: str, message: str) -> None:
    import importlib.util

    if importlib.util.find_spec(module) is None:
        raise VolSRError(message)


# -- methods --------------------------------------------------------------------------------------
@dataclass
class Method:
    """One curve point: ``frame(t, camera, previous)`` -> (image, ms render, ms after rendering)."""

    kind: str
    scale: int = 1
    spp: int = 1
    variant: str | None = None
    model: str | None = None
    state: Any = field(default=None, repr=False)

    @property
    def label(self) -> str:
        if self.kind == "native":
            return f"native {self.spp} spp"
        if self.kind == "bilinear":
            return f"native 1/{self.scale} size + bilinear"
        if self.kind == "taau":
            return f"TAAU {self.scale}x"
        return f"VolSR {self.variant} {self.scale}x"


class _Runner:
    def __init__(self, method: Method, caster, size: tuple[int, int]):
        self.method, self.caster, self.size = method, caster, size

    def frame(self, t: int, camera, previous) -> tuple[np.ndarray, float, float]:
        from volsr_core.temporal import halton_jitter, jitter_phases, render_supersampled
        from volsr_core.temporal.taau import resize_bilinear

        m, (width, height) = self.method, self.size
        if m.kind == "native":
            started = time.perf_counter()
            image = render_supersampled(self.caster, camera, width, height, spp=m.spp)
            return image, 1000 * (time.perf_counter() - started), 0.0
        if m.kind == "bilinear":
            w, h = max(1, round(width / m.scale)), max(1, round(height / m.scale))
            started = time.perf_counter()
            lr = self.caster.render(camera, w, h)
            rendered = time.perf_counter()
            image = resize_bilinear(lr.color, width, height)
            return image, 1000 * (rendered - started), 1000 * (time.perf_counter() - rendered)
        if m.kind == "taau":
            jitter = halton_jitter(t, jitter_phases(m.scale))
            started = time.perf_counter()
            lr = self.caster.render(camera, width // m.scale, height // m.scale, jitter=jitter,
                                    previous_camera=previous)
            rendered = time.perf_counter()
            image = m.state(lr.color, lr.motion, lr.jitter)
            return image, 1000 * (rendered - started), 1000 * (time.perf_counter() - rendered)
        pipeline = m.state
        image = pipeline.render(camera)
        return image, pipeline.last_timings["render_ms"], pipeline.last_timings["network_ms"]


def build_methods(scene: Scene, size: tuple[int, int], spp: Sequence[int] = SPP, factors: Sequence[int] = FACTORS,
                  scales: Sequence[int] = SCALES, models: Sequence[ModelSpec] = (), threads: int | None = 2,
                  device: str = "cpu") -> list[Method]:
    """Fresh methods (with their state: TAAU histories, VolSR pipelines) for one scene."""
    from volsr_core.temporal import TemporalUpsampler

    methods = [Method("native", spp=int(n)) for n in spp]
    methods += [Method("bilinear", scale=int(f)) for f in factors]
    methods += [Method("taau", scale=int(s), state=TemporalUpsampler(int(s))) for s in scales]
    if models:
        from volsr_core.runtime.pipeline import Pipeline

        for spec in models:
            pipeline = Pipeline(scene.volume, scene.transfer_function, spec.path, scale=spec.scale, size=size,
                                device=device, threads=threads)
            methods.append(Method("volsr", scale=spec.scale, variant=spec.variant, model=spec.path.name,
                                  state=pipeline))
    return methods


def _check_settings(size, frames, warmup, spp, factors, scales, reference_spp) -> None:
    width, height = size
    if frames < 1 or not 0 <= warmup < frames:
        raise InputError(None, f"need frames >= 1 and 0 <= warm-up < frames, got {frames} frames, {warmup} warm-up")
    if any(n < 1 or n >= reference_spp for n in spp):
        raise InputError(None, f"native spp {list(spp)} must lie in 1..{reference_spp - 1} (below the reference's "
                         f"{reference_spp} spp)")
    if any(f < 2 for f in factors):
        raise InputError(None, f"bilinear reduction factors must be at least 2, got {list(factors)}")
    bad = [s for s in scales if s < 2 or width % s or height % s]
    if bad:
        raise InputError(None, f"size {width}x{height} must be divisible by every upscaling scale (so upscaled "
                         f"frames align with the ground truth pixel for pixel); not by {bad}")


# -- the benchmark --------------------------------------------------------------------------------
def bench_scene(scene: Scene, size: tuple[int, int], methods: Sequence[Method], cameras: Sequence,
                reference_spp: int = 16, warmup: int = 4, progress=None, device: str = "cpu") -> list[dict[str, Any]]:
    """Rows (one per method) for one scene; see the module docstring for what is measured."""
    from volsr_core.render import RayCaster
    from volsr_core.sr.metrics import psnr_ssim
    from volsr_core.temporal import render_supersampled

    width, height = size
    caster = RayCaster(scene.volume, scene.transfer_function, device=device)
    truth = []
    for camera in cameras:
        truth.append(render_supersampled(caster, camera, width, height, spp=reference_spp))
        if progress is not None:
            progress.update()
    runners = [_Runner(m, caster, size) for m in methods]
    records = [{"render": [], "network": [], "psnr": [], "ssim": []} for _ in methods]
    previous = None
    for t, camera in enumerate(cameras):
        k = t % len(runners)
        for i in list(range(k, len(runners))) + list(range(k)):
            image, ms_render, ms_network = runners[i].frame(t, camera, previous)
            if t >= warmup:
                psnr, ssim = psnr_ssim(image[:height, :width], truth[t], channel_axis=-1)
                rec = records[i]
                rec["render"].append(ms_render)
                rec["network"].append(ms_network)
                rec["psnr"].append(psnr)
                rec["ssim"].append(ssim)
            if progress is not None:
                progress.update()
        previous = camera
    rows = []
    for method, rec in zip(methods, records):
        total = [a + b for a, b in zip(rec["render"], rec["network"])]
        rows.append({
            "scene": scene.label, "volume": scene.name, "preset": scene.preset,
            "range": [float(v) for v in scene.transfer_function.value_range],
            "method": method.kind, "label": method.label, "scale": method.scale, "spp": method.spp,
            "variant": method.variant, "model": method.model,
            "ms_render": _finite(statistics.median(rec["render"])),
            "ms_network": _finite(statistics.median(rec["network"])),
            "ms_total": _finite(statistics.median(total)),
            "psnr": _finite(float(np.mean(rec["psnr"]))), "ssim": _finite(float(np.mean(rec["ssim"]))),
            "psnr_frames": [_finite(v) for v in rec["psnr"]],
            "ms_total_frames": [_finite(v) for v in total],
        })
    return rows


def _finite(value: float) -> float | None:
    value = float(value)
    return round(value, 4) if math.isfinite(value) else None


def run_benchmark(volumes: Sequence[str | None] | None = None, size: tuple[int, int] = (512, 512), *,
                  frames: int = 12, degrees: float = 2.0, warmup: int = 4, reference_spp: int = 16,
                  spp: Sequence[int] = SPP, factors: Sequence[int] = FACTORS, scales: Sequence[int] = SCALES,
                  variants: Sequence[str] = VARIANTS, models_dir: str | os.PathLike | None = None,
                  preset: str | None = None, placement: str | tuple[float, float] = "auto", threads: int | None = 2,
                  device: str = "cpu", progress: bool = True) -> dict[str, Any]:
    """Benchmark every scene (volume specs, :func:`parse_scene_spec`; none: the phantom).

    Returns ``{"settings", "machine", "models", "rows", "targets"}`` (what bench.json holds).
    ``scales`` are TAAU's and the VolSR models' (``variants`` filters the models).
    """
    from tqdm import tqdm

    _require("skimage", "volsr bench measures PSNR and SSIM with scikit-image: pip install 'volsr[dev]'")
    _require("matplotlib", "volsr bench plots with matplotlib: pip install 'volsr[dev]'")
    bad = [v for v in variants if v.upper() not in VARIANTS]
    if bad:
        raise InputError(None, f"variants must come from {', '.join(VARIANTS)}, got {', '.join(bad)}")
    size = (int(size[0]), int(size[1]))
    _check_settings(size, frames, warmup, spp, factors, scales, reference_spp)
    specs = list(volumes) if volumes else [None]
    models = find_models(models_dir, variants, scales)
    scenes = [load_scene(spec, preset, placement) for spec in specs]
    n_methods = len(spp) + len(factors) + len(scales) + len(models)
    rows: list[dict[str, Any]] = []
    with tqdm(total=len(scenes) * frames * (1 + n_methods), desc="bench", unit="render", disable=not progress) as bar:
        for scene in scenes:
            bar.set_postfix_str(scene.name)
            methods = build_methods(scene, size, spp, factors, scales, models, threads, device)
            cameras = camera_path(scene.volume, frames, degrees)
            rows += bench_scene(scene, size, methods, cameras, reference_spp, warmup, bar, device)

    settings = {"size": list(size), "frames": frames, "degrees_per_frame": degrees, "warmup": warmup,
                "measured_frames": frames - warmup, "reference_spp": reference_spp, "spp": list(spp),
                "factors": list(factors), "scales": list(scales), "variants": [v.upper() for v in variants],
                "models_dir": None if models_dir is None else str(models_dir), "onnxruntime_threads": threads,
                "numba_threads": numba.get_num_threads(), "device": device}
    machine = {"python": platform.python_version(), "platform": platform.platform(),
               "processor": platform.processor() or platform.machine(), "cpu_count": os.cpu_count(),
               "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
               "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    return {"benchmark": "volsr-bench", "version": 1, "settings": settings, "machine": machine,
            "models": [{"path": str(m.path), "variant": m.variant, "scale": m.scale} for m in models],
            "rows": rows, "targets": check_targets(rows)}


# -- analysis -------------------------------------------------------------------------------------
def pareto_front(times: Sequence[float], psnrs: Sequence[float]) -> list[int]:
    """Indices of the non-dominated points (less time and more PSNR are better), by time.

    A point is dominated when another one takes no more time and gives no less PSNR, and is
    strictly better in one of them; equal points do not dominate each other.
    """
    t = np.asarray(times, dtype=np.float64)
    p = np.asarray(psnrs, dtype=np.float64)
    keep = []
    for i in range(len(t)):
        dominated = np.any((t <= t[i]) & (p >= p[i]) & ((t < t[i]) | (p > p[i])))
        if not dominated:
            keep.append(i)
    return sorted(keep, key=lambda i: (t[i], -p[i]))


def curve_psnr_at(times: Sequence[float], psnrs: Sequence[float], at: float) -> float:
    """PSNR of the curve through (time, PSNR) points at time ``at``, linear in time; beyond its ends
    the end point's PSNR (the curve is not extrapolated)."""
    order = np.argsort(np.asarray(times, dtype=np.float64), kind="stable")
    return float(np.interp(at, np.asarray(times, dtype=np.float64)[order], np.asarray(psnrs, dtype=np.float64)[order]))


def _scenes(rows: Sequence[dict]) -> list[str]:
    return list(dict.fromkeys(r["scene"] for r in rows))


def _native_1spp(rows: Sequence[dict]) -> dict | None:
    return next((r for r in rows if r["method"] == "native" and r["spp"] == 1), None)


def check_targets(rows: Sequence[dict]) -> dict[str, dict[str, Any]]:
    """The issue's targets per scene, from benchmark rows.

    1. ``fast_4x``: some VolSR model at 4x reaches at least the PSNR of native full-size 1-spp
       rendering in at most 1/3 of that rendering's time (per-model details in ``points``).
    2. ``above_bilinear``: every VolSR point lies above the native + bilinear curve at equal
       time: the curve through native 1 spp (factor 1) and the bilinear rows, sorted by time,
       its PSNR interpolated linearly in time at the VolSR point's time (beyond the curve's time
       span: the end point's PSNR; such points are flagged ``outside``).

    ``met`` is True / False, or None when the rows cannot tell (no native 1 spp, no VolSR model).
    """
    result: dict[str, dict[str, Any]] = {}
    for scene in _scenes(rows):
        mine = [r for r in rows if r["scene"] == scene]
        native = _native_1spp(mine)
        volsr = [r for r in mine if r["method"] == "volsr" and r["psnr"] is not None]
        fast: dict[str, Any] = {"met": None, "points": []}
        above: dict[str, Any] = {"met": None, "points": []}
        if native is not None and native["psnr"] is not None:
            budget = native["ms_total"] * TARGET_TIME_FRACTION
            fast.update(native_psnr=native["psnr"], native_ms=native["ms_total"], budget_ms=round(budget, 4))
            for r in volsr:
                if r["scale"] == TARGET_SCALE:
                    ok = r["psnr"] >= native["psnr"] and r["ms_total"] <= budget
                    fast["points"].append({"label": r["label"], "psnr": r["psnr"], "ms_total": r["ms_total"],
                                           "met": bool(ok)})
            if fast["points"]:
                fast["met"] = any(p["met"] for p in fast["points"])
            curve = [native] + [r for r in mine if r["method"] == "bilinear" and r["psnr"] is not None]
            times, psnrs = [r["ms_total"] for r in curve], [r["psnr"] for r in curve]
            for r in volsr:
                on_curve = curve_psnr_at(times, psnrs, r["ms_total"])
                above["points"].append({"label": r["label"], "psnr": r["psnr"], "ms_total": r["ms_total"],
                                        "curve_psnr": round(on_curve, 4), "margin_db": round(r["psnr"] - on_curve, 4),
                                        "outside": not min(times) <= r["ms_total"] <= max(times),
                                        "met": bool(r["psnr"] > on_curve)})
            if above["points"]:
                above["met"] = all(p["met"] for p in above["points"])
        result[scene] = {"fast_4x": fast, "above_bilinear": above}
    return result


def _verdict(met: bool | None) -> str:
    return {True: "**met**", False: "**not met**", None: "not evaluated"}[met]


def target_lines(targets: dict[str, Any]) -> list[str]:
    """Human-readable verdicts for one scene's :func:`check_targets` entry (markdown)."""
    fast, above = targets["fast_4x"], targets["above_bilinear"]
    lines = []
    text = (f"1. VolSR at {TARGET_SCALE}x reaches at least native 1-spp PSNR in ≤ 1/3 of its time: "
            f"{_verdict(fast['met'])}")
    if "native_psnr" in fast:
        text += (f" (native 1 spp: {fast['native_psnr']:.2f} dB in {fast['native_ms']:.1f} ms; "
                 f"budget {fast['budget_ms']:.1f} ms)")
    if fast["met"] is None:
        text += f" - no VolSR model at {TARGET_SCALE}x was benchmarked"
    lines.append(text)
    lines += [f"   - {p['label']}: {p['psnr']:.2f} dB in {p['ms_total']:.1f} ms: {'yes' if p['met'] else 'no'}"
              for p in fast["points"]]
    text = f"2. Every VolSR point lies above the native + bilinear curve at equal time: {_verdict(above['met'])}"
    if above["met"] is None:
        text += " - no VolSR model was benchmarked"
    lines.append(text)
    lines += [f"   - {p['label']}: {p['psnr']:.2f} dB vs curve {p['curve_psnr']:.2f} dB at {p['ms_total']:.1f} ms "
              f"({p['margin_db']:+.2f} dB{', beyond the curve: its end point' if p['outside'] else ''}): "
              f"{'yes' if p['met'] else 'no'}" for p in above["points"]]
    return lines


def _sorted_rows(rows: Sequence[dict]) -> list[dict]:
    return sorted(rows, key=lambda r: (METHOD_ORDER.index(r["method"]), r["scale"], r["spp"], str(r["variant"])))


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def markdown_report(results: dict[str, Any]) -> str:
    """bench.md: settings, a table per scene with ratios to native 1 spp, and the target verdicts."""
    s = results["settings"]
    width, height = s["size"]
    lines = ["# VolSR benchmark: quality against time", "",
             f"{width}x{height} pixels; camera orbiting {s['frames']} frames of {s['degrees_per_frame']:g}° each; "
             f"quality (PSNR, SSIM against a {s['reference_spp']}-spp supersampled native rendering) averaged over "
             f"the {s['measured_frames']} frames after {s['warmup']} warm-up frames; times are medians over the same "
             f"frames. All methods in one run, interleaved frame by frame; onnxruntime {s['onnxruntime_threads']} "
             f"threads, numba {s['numba_threads']} threads, device {s['device']}. "
             f"Machine: {results['machine']['processor']}, {results['machine']['cpu_count']} CPUs, "
             f"{results['machine']['date']}.", "",
             "Render = ray casting (every feature buffer, motion vectors too); network = what follows it (the "
             "network for VolSR, the upscaling for bilinear and TAAU); total is the median of the per-frame sums, so "
             "it need not equal the two medians added. Time and ΔPSNR are relative to native full-size 1-spp "
             "rendering.", ""]
    if not results["models"]:
        lines += ["No VolSR model was benchmarked (no shipped model for the chosen variants and scales, and no "
                  "`--models-dir`).", ""]
    for scene in _scenes(results["rows"]):
        mine = [r for r in results["rows"] if r["scene"] == scene]
        native = _native_1spp(mine)
        lines += [f"## {scene}", "",
                  "| method | render ms | network ms | total ms | time / native 1 spp | PSNR dB | ΔPSNR dB | SSIM |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|"]
        for r in _sorted_rows(mine):
            ratio = (f"{r['ms_total'] / native['ms_total']:.2f}" if native and native["ms_total"] and r["ms_total"]
                     is not None else "-")
            delta = (f"{r['psnr'] - native['psnr']:+.2f}" if native and native["psnr"] is not None
                     and r["psnr"] is not None else "-")
            psnr = "-" if r["psnr"] is None else f"{r['psnr']:.2f}"
            ssim = "-" if r["ssim"] is None else f"{r['ssim']:.4f}"
            lines.append(f"| {r['label']} | {_ms(r['ms_render'])} | {_ms(r['ms_network'])} | {_ms(r['ms_total'])} "
                         f"| {ratio} | {psnr} | {delta} | {ssim} |")
        lines += ["", "Targets:", ""] + target_lines(results["targets"][scene]) + [""]
    return "\n".join(lines)


def plot(results: dict[str, Any], path: str | os.PathLike) -> Path:
    """bench.png: PSNR against ms per frame, one panel per scene, Pareto front marked."""
    _require("matplotlib", "volsr bench plots with matplotlib: pip install 'volsr[dev]'")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    scenes = _scenes(results["rows"])
    cols = min(3, max(1, len(scenes)))
    n_rows = math.ceil(len(scenes) / cols) if scenes else 1
    fig, axes = plt.subplots(n_rows, cols, figsize=(5.2 * cols, 4.2 * n_rows), squeeze=False)
    styles = {"native": ("o", "C0"), "bilinear": ("s", "C1"), "taau": ("^", "C2")}
    volsr_colours = {"S": "C3", "M": "C4", "L": "C5"}
    for ax, scene in zip(axes.flat, scenes):
        mine = [r for r in _sorted_rows(results["rows"]) if r["scene"] == scene
                and r["psnr"] is not None and r["ms_total"] is not None]
        native = _native_1spp(mine)
        curve = sorted(([native] if native else []) + [r for r in mine if r["method"] == "bilinear"],
                       key=lambda r: r["ms_total"])
        if curve:
            ax.plot([r["ms_total"] for r in curve], [r["psnr"] for r in curve], "-", color="C1", lw=1, alpha=0.6,
                    label="native + bilinear curve")
        seen = set()
        for r in mine:
            marker, colour = styles.get(r["method"], ("*", volsr_colours.get(r["variant"], "C6")))
            name = {"native": "native", "bilinear": "native reduced + bilinear", "taau": "TAAU"}.get(
                r["method"], f"VolSR {r['variant']}")
            ax.plot(r["ms_total"], r["psnr"], marker, color=colour, ms=9 if r["method"] == "volsr" else 6,
                    label=None if name in seen else name)
            seen.add(name)
            short = {"native": f"{r['spp']} spp", "bilinear": f"1/{r['scale']}", "taau": f"{r['scale']}x"}.get(
                r["method"], f"{r['variant']} {r['scale']}x")
            ax.annotate(short, (r["ms_total"], r["psnr"]), textcoords="offset points", xytext=(4, 3), fontsize=7)
        front = [mine[i] for i in pareto_front([r["ms_total"] for r in mine], [r["psnr"] for r in mine])]
        if front:
            ax.plot([r["ms_total"] for r in front], [r["psnr"] for r in front], "--", color="k", lw=1.2,
                    label="Pareto front", zorder=0)
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_formatter(matplotlib.ticker.FuncFormatter(
            lambda v, _: f"{v:g}" if f"{v:g}"[0] in "25" else ""))
        ax.tick_params(axis="x", which="minor", labelsize=7)
        ax.set_xlabel("ms per frame (median)")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(scene, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for ax in list(axes.flat)[len(scenes):]:
        ax.set_visible(False)
    fig.tight_layout()
    path = Path(path)
    with atomic_write(path) as fh:
        fig.savefig(fh, format="png", dpi=120)
    plt.close(fig)
    return path


def write_outputs(results: dict[str, Any], out_dir: str | os.PathLike) -> list[Path]:
    """bench.json, bench.md and bench.png in ``out_dir`` (created), each written atomically."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "bench.json", "w", encoding="utf-8") as fh:
        json.dump(results, fh, indent=1, allow_nan=False)
        fh.write("\n")
    with atomic_write(out / "bench.md", "w", encoding="utf-8") as fh:
        fh.write(markdown_report(results))
    plot(results, out / "bench.png")
    return [out / "bench.json", out / "bench.md", out / "bench.png"]
