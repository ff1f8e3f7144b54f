"""Quality against time: native rendering, native + bilinear, TAAU and VolSR side by side.

For each scene (a volume and its placed transfer function) the camera orbits ``frames`` frames of
``degrees`` each (so temporal methods have history). Every method renders every frame, in one
run, interleaved frame by frame (the order rotating per frame, so machine noise hits all alike):

- ``native``: full size, ``spp`` jittered samples per pixel (1 = the pixel centres);
- ``bilinear``: full size / ``factor`` (VTK's ImageSampleDistance), bilinearly upscaled;
- ``taau``: full size / ``scale``, Halton-jittered, motion vectors, TAAU;
- ``volsr``: :class:`~volsr_core.runtime.pipeline.Pipeline` for every model (variant, scale), and for each
  ``stretches`` k > 1 every model whose scale times k is one of ``scales``, its image stretched by k
  (``Pipeline(..., stretch=k)``, bicubic: a point at that scale, "VolSR XS 2x + bicubic 2x" at 4x);

all of them :mod:`volsr_core.runtime.methods`.

Each is compared with a supersampled native ground truth (``reference_spp`` Halton samples per pixel,
:func:`render_supersampled`; rendered for the scored frames alone) by PSNR and SSIM (scikit-image; the scored pass's
images are kept and scored after it, on every core, so no scoring runs between the methods' frames; they are kept in
one store per method, one block allocated at its first scored frame: a copy allocated anew per frame grew the memory
the methods take their images from between their frames, and in that pass alone every method's frames took longer,
by about 17 ms at 1024² on a run's first volume; docs/performance.md, "The scored pass timed its own bookkeeping").
Quality is averaged over the frames after ``warmup`` warm-up frames; times are medians over the same frames of
``timing_passes`` passes over the orbit: the scored one and ``timing_passes - 1`` more with fresh methods (their
histories empty again), timed and not scored (the warm-up also absorbs kernel compilation). A method's time on this
2-core machine moves by 10-40% from frame to frame (the orbit's views and the machine alike), so the median of one
pass's 8 frames moved the margins by up to 1.2 dB between runs at 1024² (docs/performance.md).
``ms_render`` is the ray casting, ``ms_network`` what follows it (TAAU and the network for VolSR, the bilinear or
TAAU upscaling for those, 0 for native), ``ms_total`` their sum; ``ms_total_passes`` each pass's median.
On ``device="cuda"`` every method makes its full-size image on the GPU and its times end when the GPU is done;
``ms_readback``, the image's copy to the host for scoring (0 on the CPU), is not in ``ms_total``.

:func:`run_benchmark` runs it; :mod:`volsr_core.apps.bench.report` checks the targets
(docs/performance.md) and writes bench.json, bench.md and bench.png; the volumes come from
:mod:`volsr_core.apps.bench.scenes`. ``volsr bench`` is the command-line wrapper.
"""
from __future__ import annotations

import math
import os
import platform
import statistics
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numba
import numpy as np

from volsr_core.apps.bench.report import check_targets
from volsr_core.apps.bench.scenes import BenchVolume, load_bench_volume
from volsr_core.errors import InputError, require
from volsr_core.render.device import to_host
from volsr_core.render.raycaster import RayCaster
from volsr_core.runtime.methods import Method, Native, ReducedSize, Taau, VolSR
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.sr.network_config import VARIANTS

SPP = (1, 2, 4)
FACTORS = (2, 3, 4, 6, 8)
SCALES = (2, 4, 8)
STRETCHES = (2,)


# -- models ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ModelSpec:
    """An ONNX model file with the scale and variant its metadata says."""

    path: Path
    variant: str
    scale: int


def infer_variant(config) -> str | None:
    """The variant (:data:`VARIANTS`) ``config`` (a NetworkConfig) is, else None: XS without a U-Net, else the U-Net
    variant of its fold (S folds by the scale, M by half of it, L by a quarter; a model's widths are its own, the
    shipped S 2x and S 4x narrower than ``variant_config``'s), where two share the fold (M and L at 2x) the one whose
    widths it has, else the smaller."""
    from volsr_core.sr.network_config import variant_config

    if not config.widths:
        return "XS" if config.base_kernel else None
    candidates = []
    for rank, name in enumerate(VARIANTS):
        try:
            reference = variant_config(name, config.scale, config.previous_frames, config.features,
                                       recurrent=config.recurrent, taau_base=config.taau_base)
        except ValueError:
            continue
        if reference.widths and reference.fold == config.fold:
            candidates.append((reference.widths != config.widths, rank, name))
    return min(candidates)[2] if candidates else None


def find_models(models_dir: str | os.PathLike | None = None, variants: Sequence[str] = VARIANTS,
                scales: Sequence[int] = SCALES, device: str = "cpu") -> list[ModelSpec]:
    """The models to benchmark, by scale then variant.

    Without ``models_dir``: the shipped registry's (:func:`~volsr_core.runtime.models.shipped_models`,
    SHA-256 checked), each the file hosts run on ``device`` (:func:`~volsr_core.runtime.models.model_file_to_run`:
    on the CPU the 8-bit one where it ships). With it: every ``*.onnx`` in the folder, scale and variant read from the
    model's metadata (:class:`OnnxEngine`, :func:`infer_variant`); a model that is no named variant, or one of
    two or more of the same variant and scale (a model beside its retrained self), goes by its file name and is
    kept whatever ``variants`` says. Only ``scales`` are kept.
    """
    wanted = {v.upper() for v in variants}
    found: list[ModelSpec] = []
    if models_dir is None:
        from volsr_core.runtime.models import model_file_to_run, shipped_models

        for entry in shipped_models():
            if entry["variant"] in wanted and entry["scale"] in scales and "onnx" in entry.get("files", {}):
                found.append(ModelSpec(model_file_to_run(entry["variant"], entry["scale"], device), entry["variant"],
                                       int(entry["scale"])))
    else:
        folder = Path(models_dir)
        if not folder.is_dir():
            raise InputError(folder, "is not a folder of .onnx models")
        paths = sorted(folder.glob("*.onnx"))
        if not paths:
            raise InputError(folder, "holds no .onnx models")
        require("onnxruntime", "VolSR models run in onnxruntime: pip install 'volsr[onnx]'")
        from volsr_core.runtime.engines import OnnxEngine

        configs = {path: OnnxEngine(path, providers=["CPUExecutionProvider"]).config for path in paths}
        variants = {path: infer_variant(config) for path, config in configs.items()}
        named = Counter((variants[path], config.scale) for path, config in configs.items())
        for path, config in configs.items():
            variant = variants[path] if named[variants[path], config.scale] == 1 else None
            if config.scale in scales and (variant is None or variant in wanted):
                found.append(ModelSpec(path, variant or path.stem, int(config.scale)))
    return sorted(found, key=lambda m: (m.scale, VARIANTS.index(m.variant) if m.variant in VARIANTS else 9,
                                        str(m.path)))


def model_scales(scales: Sequence[int], stretches: Sequence[int] = STRETCHES) -> list[int]:
    """The model scales the VolSR rows need: ``scales``, and each divided by each of ``stretches`` where it divides
    into a scale of 2 or more."""
    return sorted({s // k for s in scales for k in (1, *stretches) if s % k == 0 and s // k >= 2})


def volsr_rows(models: Sequence[ModelSpec], scales: Sequence[int],
               stretches: Sequence[int] = STRETCHES) -> list[tuple[ModelSpec, int]]:
    """(model, stretch) of every VolSR row: each model at a scale of ``scales`` as it is (stretch 1), and each whose
    scale times a k > 1 of ``stretches`` is one of ``scales``, stretched by k (a point at that scale)."""
    return [(spec, k) for spec in models for k in dict.fromkeys((1, *stretches)) if spec.scale * k in scales]


def build_methods(bench_volume: BenchVolume, caster: RayCaster, size: tuple[int, int], spp: Sequence[int] = SPP,
                  factors: Sequence[int] = FACTORS, scales: Sequence[int] = SCALES,
                  models: Sequence[tuple[ModelSpec, int]] = (), threads: int | None = 2, device: str = "cpu",
                  vtk: str | None = None) -> list[Method]:
    """Fresh methods (with their state: TAAU histories, VolSR pipelines) for one volume; native, bilinear
    and TAAU share ``caster``; ``models`` are (model, stretch) pairs (:func:`volsr_rows`); ``vtk`` ("gpu",
    "fixed_point") adds VTK's own mapper at full size."""
    methods: list[Method] = [Native(caster, size, int(n)) for n in spp]
    methods += [ReducedSize(caster, size, int(f), "bilinear") for f in factors]
    methods += [Taau(caster, size, int(s)) for s in scales]
    if models:
        from volsr_core.runtime.pipeline import Pipeline

        for spec, stretch in models:
            pipeline = Pipeline(bench_volume.volume, bench_volume.transfer_function, spec.path,
                                scale=spec.scale * stretch, size=size, device=device, threads=threads, stretch=stretch)
            methods.append(VolSR(pipeline, spec.variant, spec.path.name))
    if vtk is not None:
        from volsr_core.hosts.vtk_reference import VtkMethod

        methods.append(VtkMethod(bench_volume.volume, bench_volume.transfer_function, size, vtk))
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


def cpu_description(cpuinfo: str = "/proc/cpuinfo") -> str | None:
    """The CPU's model name and its widest vector instructions ("AMD EPYC, AVX2"), read from ``cpuinfo`` (Linux);
    None where that is not there. The networks' times depend on them: onnxruntime ran the S network at 512² in
    20.6 ms with AVX-512 VNNI and 37.7 ms with AVX2 alone on the project's machines (docs/performance.md)."""
    try:
        text = Path(cpuinfo).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    fields = {key.strip(): value for key, value in (line.split(":", 1) for line in text.splitlines() if ":" in line)}
    name = " ".join(fields.get("model name", "").split())
    flags = set(fields.get("flags", "").split())
    vector = next((label for flag, label in (("avx512_vnni", "AVX-512 VNNI"), ("avx512f", "AVX-512"), ("avx2", "AVX2"),
                                             ("avx", "AVX")) if flag in flags), "no AVX")
    return f"{name or 'unknown model'}, {vector}"


# -- the benchmark --------------------------------------------------------------------------------
def _one_pass(methods: Sequence[Method], cameras: Sequence, warmup: int, turn: int, measured, progress=None) -> None:
    """Every method renders every camera in order, interleaved frame by frame, the first method rotating with the
    frame (and by ``turn`` between passes) so machine noise hits all alike; ``measured(i, t, frame)`` gets method
    i's frame t after the warm-up."""
    for t, camera in enumerate(cameras):
        k = (t + turn) % len(methods)
        for i in list(range(k, len(methods))) + list(range(k)):
            frame = methods[i](camera)
            if t >= warmup:
                measured(i, t, frame)
            if progress is not None:
                progress.update()


def bench_one(bench_volume: BenchVolume, caster: RayCaster, size: tuple[int, int], methods: Sequence[Method],
              cameras: Sequence, reference_spp: int = 16, warmup: int = 4, progress=None,
              timing_passes: Iterable[Sequence[Method]] = ()) -> list[dict[str, Any]]:
    """Rows (one per method) for one volume; see the module docstring for what is measured.

    ``timing_passes``: fresh method lists (the same methods, in the same order, each built anew) for the passes
    after the scored one, taken one at a time (a generator builds each only when its pass starts)."""
    from volsr_core.sr.metrics import psnr_ssim_many
    from volsr_core.temporal.ground_truth import supersampled_truth

    width, height = size
    truth = {}  # frame -> its ground truth, for the scored frames alone (the warm-up's would go unused)
    for t, camera in enumerate(cameras[warmup:], start=warmup):
        image = supersampled_truth(caster, camera, t, width, height, reference_spp,
                                   on_device=caster.device == "cuda")  # on a GPU summed there, one copy back
        truth[t] = to_host(image)[0]
        if progress is not None:
            progress.update()
    records = [{"render": [], "network": [], "readback": [], "psnr": [], "ssim": [], "passes": []} for _ in methods]
    kept: list[tuple[int, np.ndarray, np.ndarray]] = []  # the scored pass's images, scored after it
    stores: dict[int, np.ndarray] = {}  # per method, its scored frames' images (see the module docstring)

    def timed(i: int, t: int, frame) -> None:
        rec = records[i]
        rec["render"].append(frame.ms_render)
        rec["network"].append(frame.ms_upscale)
        rec["readback"].append(frame.ms_readback)

    def scored(i: int, t: int, frame) -> None:
        timed(i, t, frame)
        image = frame.image[:height, :width]
        if i not in stores:
            stores[i] = np.zeros((len(cameras) - warmup,) + image.shape, image.dtype)  # one block, its own pages
        store = stores[i][t - warmup]
        store[...] = image  # a copy: a method may reuse its buffer
        kept.append((i, store, truth[t]))

    def end_pass() -> None:
        for rec in records:
            rec["passes"].append(len(rec["render"]))

    _one_pass(methods, cameras, warmup, 0, scored, progress)
    end_pass()
    if progress is not None:  # a minute or more at 1024² on two cores, between two passes' renders
        progress.set_postfix_str(f"{bench_volume.name}: scoring {len(kept)} images")
    for (i, _, _), (psnr, ssim) in zip(kept, psnr_ssim_many([(image, t) for _, image, t in kept], channel_axis=-1)):
        records[i]["psnr"].append(psnr)
        records[i]["ssim"].append(ssim)
    kept.clear()
    stores.clear()
    if progress is not None:
        progress.set_postfix_str(bench_volume.name)
    for turn, fresh in enumerate(timing_passes, start=1):
        if [m.label for m in fresh] != [m.label for m in methods]:
            raise ValueError("a timing pass must run the scored pass's methods, in its order")
        _one_pass(fresh, cameras, warmup, turn, timed, progress)
        end_pass()
    rows = []
    for method, rec in zip(methods, records):
        total = [a + b for a, b in zip(rec["render"], rec["network"])]
        ends = rec["passes"]
        by_pass = [total[start:end] for start, end in zip([0] + ends[:-1], ends)]
        rows.append({
            "scene": bench_volume.label, "volume": bench_volume.name, "preset": bench_volume.preset,
            "range": [float(v) for v in bench_volume.transfer_function.value_range],
            "method": method.kind, "label": method.label, "scale": method.scale, "spp": method.spp,
            "slabs": method.slabs, "stretch": method.stretch, "variant": method.variant, "model": method.model,
            "ms_render": _finite(statistics.median(rec["render"])),
            "ms_network": _finite(statistics.median(rec["network"])),
            "ms_total": _finite(statistics.median(total)),
            "ms_readback": _finite(statistics.median(rec["readback"])),
            "psnr": _finite(float(np.mean(rec["psnr"]))), "ssim": _finite(float(np.mean(rec["ssim"]))),
            "psnr_frames": [_finite(v) for v in rec["psnr"]],
            "ms_total_frames": [_finite(v) for v in total],  # pass after pass, the scored one first
            "ms_total_passes": [_finite(statistics.median(times)) for times in by_pass],
        })
    return rows


def _finite(value: float) -> float | None:
    value = float(value)
    return round(value, 4) if math.isfinite(value) else None


def run_benchmark(volumes: Sequence[str | None] | None = None, size: tuple[int, int] = (512, 512), *,
                  frames: int = 12, degrees: float = 2.0, warmup: int = 4, reference_spp: int = 16,
                  spp: Sequence[int] = SPP, factors: Sequence[int] = FACTORS, scales: Sequence[int] = SCALES,
                  stretches: Sequence[int] = STRETCHES, variants: Sequence[str] = VARIANTS,
                  models_dir: str | os.PathLike | None = None,
                  preset: str | None = None, placement: str | tuple[float, float] = "auto", threads: int | None = 2,
                  device: str = "cpu", progress: bool = True, vtk: str | None = None,
                  timing_passes: int = 3) -> dict[str, Any]:
    """Benchmark every volume (specs, :func:`~volsr_core.apps.bench.scenes.parse_volume_spec`; none: the phantom).

    Returns ``{"settings", "machine", "models", "rows", "targets"}`` (what bench.json holds).
    ``scales`` are TAAU's and the VolSR models' (``variants`` filters the models); ``stretches`` add the stretched
    VolSR rows (:func:`volsr_rows`; (1,) or () for none); ``timing_passes`` (1 or more) the passes over the orbit
    whose times count (the module docstring).
    """
    from tqdm import tqdm

    require("skimage", "volsr bench measures PSNR and SSIM with scikit-image: pip install 'volsr[dev]'")
    require("matplotlib", "volsr bench plots with matplotlib: pip install 'volsr[dev]'")
    bad = [v for v in variants if v.upper() not in VARIANTS]
    if bad:
        raise InputError(None, f"variants must come from {', '.join(VARIANTS)}, got {', '.join(bad)}")
    size = (int(size[0]), int(size[1]))
    _check_settings(size, frames, warmup, spp, factors, scales, reference_spp)
    if timing_passes < 1:
        raise InputError(None, f"need at least 1 timing pass (the scored one), got {timing_passes}")
    specs = list(volumes) if volumes else [None]
    models = find_models(models_dir, variants, model_scales(scales, stretches), device)
    rows_of_models = volsr_rows(models, scales, stretches)
    models = list(dict.fromkeys(spec for spec, _ in rows_of_models))  # those a row runs
    volumes_ = [load_bench_volume(spec, preset, placement) for spec in specs]
    n_methods = len(spp) + len(factors) + len(scales) + len(rows_of_models) + (vtk is not None)
    rows: list[dict[str, Any]] = []
    renders = len(volumes_) * (frames - warmup + frames * n_methods * timing_passes)  # the truth's, the methods'
    with tqdm(total=renders, desc="bench", unit="render", disable=not progress) as bar:
        for bench_volume in volumes_:
            bar.set_postfix_str(bench_volume.name)
            caster = RayCaster(bench_volume.volume, bench_volume.transfer_function, device=device, start_jitter="ign")

            def fresh_methods() -> list[Method]:
                return build_methods(bench_volume, caster, size, spp, factors, scales, rows_of_models, threads,
                                     device, vtk)

            cameras = orbit_around(caster.visible_bounds(), frames, degrees, aspect=size[0] / size[1])
            more = (fresh_methods() for _ in range(timing_passes - 1))
            rows += bench_one(bench_volume, caster, size, fresh_methods(), cameras, reference_spp, warmup, bar, more)

    settings = {"size": list(size), "frames": frames, "degrees_per_frame": degrees, "warmup": warmup,
                "measured_frames": frames - warmup, "timing_passes": timing_passes,
                "timed_frames": (frames - warmup) * timing_passes, "reference_spp": reference_spp, "spp": list(spp),
                "factors": list(factors), "scales": list(scales), "stretches": list(stretches),
                "variants": [v.upper() for v in variants],
                "models_dir": None if models_dir is None else str(models_dir), "onnxruntime_threads": threads,
                "numba_threads": numba.get_num_threads(), "device": device, "vtk": vtk}
    machine = {"python": platform.python_version(), "platform": platform.platform(),
               "processor": platform.processor() or platform.machine(), "cpu_count": os.cpu_count(),
               "cpu": cpu_description(),
               "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
               "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    return {"benchmark": "volsr-bench", "version": 1, "settings": settings, "machine": machine,
            "models": [{"path": str(m.path), "variant": m.variant, "scale": m.scale} for m in models],
            "rows": rows, "targets": check_targets(rows)}


