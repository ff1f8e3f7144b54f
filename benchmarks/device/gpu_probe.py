"""What each method's frame would cost on a GPU if it stayed there: its parts timed on the device, and the
``volsr bench`` PSNRs of the CPU runs placed at those times (a projection, not a run).

    python benchmarks/device/gpu_probe.py OUT [--bench docs/bench] [--sizes 512,1024] [--names CT_AVM,LIDC2,...]
                                          [--volumes DIR] [--repeats 15] [--torch-device cuda]

On the lent H200 (docs/performance-gpu.md) every frame's 14-15 float32 feature channels travelled to host memory,
and that copy, not the ray march, set every method's time. A viewer displays from the device, so the question
the next step (render, TAAU and filter kept on the device) has to answer first is where the methods would lie
without the copy. Per bench volume and output size this measures, with the device synchronised around each call
(medians of ``--repeats`` after a warm-up):

- the CUDA ray cast alone (``_render_pixels``, all buffers already on the device), at every size the bench
  renders: full size (native; N spp = N casts), round(size / F) (native 1/F size), size / S with motion
  vectors and, where the bench's VolSR row had them, depth slabs;
- the bilinear upscale on the device (:func:`~volsr_core.temporal.frames_cuda.resize_bilinear_device`, what the
  bench's baseline runs on a CUDA caster, as a GPU viewer stretches);
- TAAU and the layered TAAU as CUDA kernels (:mod:`volsr_core.temporal.cuda`) on a frame rendered and left on the
  device, for VolSR XS with its filter (:mod:`volsr_core.runtime.base_filter_cuda`) after it: what
  ``Pipeline(device="cuda")`` does for XS, whose rows the bench on the GPU now measures end to end too;
- each shipped U-Net's network on ``--torch-device`` at its LR size, inputs already there, after its TAAU on the
  device (without the side outputs the S and M models also read: a lower bound on their step);

no method's image is copied to the host (the bench on the GPU times that copy apart, the same for every method),
and prices each row of the CPU run's ``bench.json`` (``--bench``/<size>-2deg; PSNRs do not depend on the device:
equal to 0.01 dB on the H200) by them: where each method would lie against the native + bilinear curve were its
frame kept on the device, which is what decides whether that can pay. Writes ``OUT/probe.json`` and
``OUT/probe.md`` (the parts, then per volume each row's projected ms, PSNR and, for VolSR, its margin over the
projected native + bilinear curve, ``check_targets``' target 2; last, what a kernel launch, an allocation, an upload
and a round trip cost on the host side, :func:`host_side_ms`).

Volumes come as ``gpu_bench.py pack`` records (``--volumes``, default ``benchmarks/device/volumes``); here,
``NUMBA_ENABLE_CUDASIM=1 ... --sizes 16 --torch-device cpu`` runs it through numba's CUDA simulator on the
phantom's rows of a small CPU bench (``--names phantom``) to check the script, not to time anything.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from gpu_bench import SCENES, read_packed  # noqa: E402

from volsr_core.apps.bench.report import check_targets  # noqa: E402
from volsr_core.apps.bench.scenes import load_bench_volume  # noqa: E402
from volsr_core.render.raycaster import RayCaster  # noqa: E402
from volsr_core.scene import Volume  # noqa: E402
from volsr_core.scene.camera_paths import orbit_around  # noqa: E402

MODELS = (("XS", 2), ("S", 2), ("XS", 4), ("S", 4), ("M", 4), ("S", 8))


def median_ms(call: Callable[[], None], sync: Callable[[], None], repeats: int) -> float:
    """Median ms of ``call`` (``sync`` waits for the device), after two warm-up calls."""
    for _ in range(2):
        call()
    sync()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        call()
        sync()
        times.append(1000.0 * (time.perf_counter() - started))
    return statistics.median(times)


class MarchTimer:
    """The CUDA ray cast of one caster alone: every input and output allocated on the device once per size."""

    def __init__(self, caster: RayCaster, cameras: list, repeats: int):
        from numba import cuda

        from volsr_core.render.cuda import THREADS, _render_pixels

        self.cuda, self.kernel, self.threads = cuda, _render_pixels, THREADS
        self.caster, self.cameras, self.repeats = caster, cameras, repeats
        caster._cuda_volume.set_empty(caster._empty)
        t = caster.tables
        self.static = [cuda.to_device(a) for a in (t.rgba, t.gradient_opacity)]
        self.geometry = [cuda.to_device(a) for a in (caster._w2i, caster._grad_w)]

    def ms(self, width: int, height: int, moving: bool, slabs: int = 0) -> float:
        """Median ms of casting ``width`` x ``height`` rays (``moving``: with the previous camera's motion vectors)."""
        from volsr_core.render.layout import OUT_CHANNELS, SLAB_CHANNELS

        cuda, caster = self.cuda, self.caster
        camera, previous = self.cameras[1], self.cameras[0]
        cam = cuda.to_device(caster._camera_array(camera, width, height, (0.0, 0.0)))
        prev_vp = cuda.to_device(np.ascontiguousarray(previous.view_projection(width / height)
                                                      if moving else np.eye(4)))
        params = cuda.to_device(caster._params(1, moving, slabs))
        out = cuda.device_array((height, width, OUT_CHANNELS), np.float32)
        slab_out = cuda.device_array((slabs, height, width, SLAB_CHANNELS) if slabs else (1, 1, 1, SLAB_CHANNELS),
                                     np.float32)
        blocks = ((width + self.threads[0] - 1) // self.threads[0], (height + self.threads[1] - 1) // self.threads[1])
        volume = caster._cuda_volume

        def cast() -> None:
            self.kernel[blocks, self.threads](volume.vol, volume.empty, *self.static, cam, *self.geometry, params,
                                              prev_vp, out, slab_out)

        return median_ms(cast, cuda.synchronize, self.repeats)


def network_ms(torch, variant: str, scale: int, height: int, width: int, device: str, repeats: int) -> float:
    """Median ms of the shipped ``variant`` ``scale``x network (its .pt) on ``device``, inputs already there."""
    from volsr_core.runtime.export import example_inputs
    from volsr_core.runtime.models import model_file
    from volsr_core.sr.checkpoint import load_model

    model = load_model(model_file(variant, scale, "pt")).to(device).eval()
    inputs = [x.to(device) for x in example_inputs(model.config, height, width)]
    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
    with torch.no_grad():
        return median_ms(lambda: model(*inputs), sync, repeats)


def post_ms(caster: RayCaster, cameras: list, lr: int, scale: int, slabs: int, variant: str | None,
            repeats: int) -> float:
    """Median ms of what follows the ray cast of a moving ``lr``² frame on the device: the TAAU (with ``slabs``, the
    layered TAAU: :mod:`volsr_core.temporal.cuda`) and, for ``variant`` "XS", its filter after it
    (:mod:`volsr_core.runtime.base_filter_cuda`), as ``Pipeline(device="cuda")`` and the bench's TAAU on the device
    run them; the frame rendered there once."""
    from numba import cuda

    from volsr_core.runtime.base_filter_cuda import CudaBaseFilter
    from volsr_core.runtime.engines import open_engine
    from volsr_core.runtime.models import model_file
    from volsr_core.temporal.cuda import CudaLayeredUpsampler, CudaTemporalUpsampler
    from volsr_core.temporal.jitter import halton_jitter, jitter_phases
    from volsr_core.temporal.taau import view_rotation

    frames = [caster.render(camera, lr, lr, jitter=halton_jitter(t, jitter_phases(scale)), seed=t, slabs=slabs,
                            previous_camera=cameras[t - 1] if t else None, on_device=True)
              for t, camera in enumerate(cameras[:2])]
    upsampler = CudaLayeredUpsampler(scale) if slabs else CudaTemporalUpsampler(scale)
    rotation = view_rotation(cameras[1], cameras[0])
    device_filter = CudaBaseFilter(*open_engine(model_file("XS", scale, "onnx")).base_filter) if variant == "XS" \
        else None

    def accumulate(frame):
        if slabs:
            return upsampler(frame.slabs, frame.jitter, caster.background, rotation, frame.pixels_per_voxel)
        return upsampler(frame.color, frame.motion, frame.jitter, frame.motion_depth, rotation, frame.pixels_per_voxel)

    def step() -> None:
        image = accumulate(frames[1])
        if device_filter is not None:
            device_filter.filter(image, clip_output=True)

    accumulate(frames[0])
    return median_ms(step, cuda.synchronize, repeats)


def bilinear_ms(height: int, width: int, out_height: int, out_width: int, repeats: int) -> float:
    """Median ms of the bench's bilinear stretch of a ``width`` x ``height`` device image to the output size."""
    from numba import cuda

    from volsr_core.temporal.frames_cuda import resize_bilinear_device

    image = cuda.to_device(np.random.default_rng(0).random((height, width, 3), dtype=np.float32))
    return median_ms(lambda: resize_bilinear_device(image, out_width, out_height), cuda.synchronize, repeats)


def bicubic_ms(height: int, width: int, out_height: int, out_width: int, repeats: int) -> float:
    """Median ms of VolSR's stretch (Keys' cubic, clamped to [0, 1] in the same pass: what
    ``Pipeline(..., stretch=k)`` runs on the device) of a ``width`` x ``height`` device image to the output size."""
    from numba import cuda

    from volsr_core.runtime.upscaler import STRETCH_CUBIC_A
    from volsr_core.temporal.frames_cuda import resize_bicubic_device

    image = cuda.to_device(np.random.default_rng(0).random((height, width, 3), dtype=np.float32))
    def stretch() -> None:
        resize_bicubic_device(image, out_width, out_height, a=STRETCH_CUBIC_A, clamp=(0.0, 1.0))

    return median_ms(stretch, cuda.synchronize, repeats)


def host_side_ms(repeats: int) -> dict[str, float]:
    """Median ms of the per-frame calls a frame on the device pays beside its kernels' work, each alone: a kernel
    launch through numba-cuda (one thread, one array argument), a new device array of two 1024² slab histories
    (40 MB), a small upload (a camera array) and a 4-byte copy back (a flag: a round trip). XS's device path makes
    about eight launches, six allocations, five uploads and two round trips a frame, native 1 spp one, two, three
    and none: set against the cast and kernel times above, they say whether pooling them can move a verdict."""
    from numba import cuda

    import volsr_core.temporal.cuda  # noqa: F401  (NumPy >= 2.5: puts back np.row_stack before numba-cuda compiles)

    @cuda.jit
    def touch(a):
        a[0] += 1.0

    flag, cam = cuda.to_device(np.zeros(1, np.float32)), np.zeros(32, np.float64)
    return {"kernel launch": median_ms(lambda: touch[1, 1](flag), cuda.synchronize, repeats),
            "device array of 40 MB": median_ms(lambda: cuda.device_array((2, 1024, 1024, 5), np.float32),
                                               cuda.synchronize, repeats),
            "upload of 256 bytes": median_ms(lambda: cuda.to_device(cam), cuda.synchronize, repeats),
            "copy back of 4 bytes": median_ms(lambda: flag.copy_to_host(), cuda.synchronize, repeats)}


def probe_volume(spec: str, size: int, cpu_rows: list[dict], torch_device: str, repeats: int) -> dict:
    """The parts and the priced rows of one volume at ``size``²."""
    import torch

    scene = load_bench_volume(spec)
    caster = RayCaster(scene.volume, scene.transfer_function, device="cuda", start_jitter="ign")
    cameras = orbit_around(caster.visible_bounds(), 2, 2.0)
    march = MarchTimer(caster, cameras, repeats)
    parts: dict[str, float] = {}

    def part(name: str, measure: Callable[[], float]) -> float:
        if name not in parts:
            parts[name] = measure()
        return parts[name]

    priced = []
    for row in cpu_rows:
        s = row["scale"]
        if row["method"] == "native":
            render, after = row["spp"] * part(f"cast {size}²", lambda: march.ms(size, size, False)), 0.0
        elif row["method"] == "bilinear":
            lr = max(1, round(size / s))
            render = part(f"cast {lr}²", lambda: march.ms(lr, lr, False))
            after = part(f"bilinear {lr}² -> {size}²", lambda: bilinear_ms(lr, lr, size, size, repeats))
        elif row["method"] in ("taau", "volsr"):
            stretch = row.get("stretch") or 1  # "+ bicubic Kx": the model at s / K, its image stretched by K
            lr, slabs, s = size // s, row.get("slabs") or 0, s // stretch
            layers = f" in {slabs} slabs" if slabs else ""
            render = part(f"cast {lr}² moving{layers}", lambda: march.ms(lr, lr, True, slabs))
            xs = row["method"] == "volsr" and row["variant"] == "XS"
            if row["method"] == "taau" or xs:  # the whole step on the device
                name = f"TAAU {s}x{layers}" + (" + XS filter" if xs else "") + f" at {lr}²"
                after = part(name, lambda: post_ms(caster, cameras, lr, s, slabs, row.get("variant"), repeats))
            else:  # a U-Net: the TAAU it refines on the device, then the network on its inputs there
                after = part(f"TAAU {s}x at {lr}²", lambda: post_ms(caster, cameras, lr, s, 0, None, repeats))
                after += part(f"network {row['variant']} {s}x at {lr}²",
                              lambda: network_ms(torch, row["variant"], s, lr, lr, torch_device, repeats))
            if stretch > 1:
                model_size = lr * s
                after += part(f"bicubic {model_size}² -> {size}²",
                              lambda: bicubic_ms(model_size, model_size, size, size, repeats))
        else:
            continue
        priced.append({**row, "ms_render": round(render, 4), "ms_network": round(after, 4),
                       "ms_total": round(render + after, 4)})
    return {"scene": priced[0]["scene"] if priced else spec, "parts": {k: round(v, 4) for k, v in parts.items()},
            "rows": priced, "targets": check_targets(priced)}


def markdown(results: list[dict], header: str) -> str:
    lines = [header, ""]
    for result in results:
        lines += [f"## {result['scene']}, {result['size']}²", "", "| part | ms |", "|---|---:|"]
        lines += [f"| {name} | {ms:.3f} |" for name, ms in result["parts"].items()]
        margins = {p["label"]: p for t in result["targets"].values() for p in t["above_bilinear"]["points"]}
        lines += ["", "| method | cast ms | after ms | total ms | PSNR dB (CPU run) | dB above the curve |",
                  "|---|---:|---:|---:|---:|---:|"]
        for row in result["rows"]:
            margin = margins.get(row["label"])
            lines.append(f"| {row['label']} | {row['ms_render']:.3f} | {row['ms_network']:.3f} | "
                         f"{row['ms_total']:.3f} | {row['psnr']:.2f} | "
                         f"{'' if margin is None else format(margin['margin_db'], '+.2f')} |")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--bench", type=Path, default=Path("docs/bench"), help="folder of the CPU runs' <size>-2deg/")
    parser.add_argument("--sizes", default="512,1024")
    parser.add_argument("--names", default=",".join(SCENES))
    parser.add_argument("--volumes", type=Path, default=Path(__file__).parent / "volumes")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--torch-device", default="cuda")
    args = parser.parse_args(argv)
    if args.volumes.is_dir():
        Volume.load = read_packed(args.volumes)
    args.out.mkdir(parents=True, exist_ok=True)
    header = (f"# Frames kept on the device: a projection\n\nParts timed by `benchmarks/device/gpu_probe.py` "
              f"(torch on {args.torch_device}, medians of {args.repeats}); PSNRs from the CPU runs in {args.bench}; "
              "TAAU, the layered TAAU and XS's filter as CUDA kernels on frames left on the device; a U-Net's "
              "network timed apart, its inputs there (its TAAU's side outputs not computed).")
    host_side = host_side_ms(args.repeats)
    results = []
    for size in (int(s) for s in args.sizes.split(",")):
        rows = json.loads((args.bench / f"{size}-2deg" / "bench.json").read_text())["rows"]
        for name in args.names.split(","):
            spec = SCENES.get(name, name)
            mine = [r for r in rows if r["volume"] == spec.split(":")[0] or name == "phantom"]
            started = time.time()
            result = probe_volume(spec if name != "phantom" else None, size, mine, args.torch_device, args.repeats)
            results.append({"size": size, **result})
            # after each volume: a run cut short keeps what it measured
            (args.out / "probe.json").write_text(json.dumps({"host_side_ms": host_side, "volumes": results}, indent=1))
            (args.out / "probe.md").write_text(markdown(results, header) + "\n## Per-call costs beside the kernels\n\n"
                                               "| call | ms |\n|---|---:|\n"
                                               + "".join(f"| {k} | {ms:.4f} |\n" for k, ms in host_side.items()))
            print(f"== {size}² {name}: {time.time() - started:.0f} s", flush=True)

if __name__ == "__main__":
    main(sys.argv[1:])
