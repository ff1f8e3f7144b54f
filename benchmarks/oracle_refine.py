"""Would spending rays where the upscaler is wrong pay? VolSR XS's frame with a fraction of its pixels re-rendered
at full size, chosen by the LR frame's local contrast (what a renderer could know) or by the true error (an
oracle), against the native + bilinear renders of the same time.

    python benchmarks/oracle_refine.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--sizes 512] [--scales 2,4]
                                       [--degrees 2] [--frames 9] [--fractions 0.05,0.1,0.2,0.3]

The shipped XS model of each scale runs a ``Pipeline`` along the benchmark's orbit; on its last frame, the
``--fractions`` of output pixels ranked highest by (a) the 3x3 range of the LR frame's luma around the pixel's
LR sample and (b) the squared error of XS's output against the 16-spp reference take the native 1-spp render's
value. The cost of those rays is measured by casting just them (the renderer's ray program over a pixel list)
against a full native render, interleaved, the median of ``--repeats`` (rays differ in cost, and the
high-contrast ones cross the most material), and added to XS's median ms per frame on the orbit. Printed per
fraction: XS's frame + those rays as a share of a native frame's time and the PSNR (dB) against the reference;
beside them the native renders at 1/2, 1/3 and 1/4 size + bilinear with their share of a native frame's time:
at equal time, the higher PSNR wins.
"""
from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numba
import numpy as np
from bench_taau import orbit_parser, orbit_scene

from volsr_core.render import RayCaster
from volsr_core.render.cpu import march_ray
from volsr_core.render.layout import SLAB_CHANNELS
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene.camera import Camera
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.temporal import render_supersampled
from volsr_core.temporal.resample import resize_bilinear

WARMUP = 4  # orbit frames before XS's frame times count (history, compilation)
LUMA = np.array([0.25, 0.5, 0.25], dtype=np.float32)


@numba.njit(parallel=True, fastmath=True)
def _cast_pixels(pixels, vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs):
    for i in numba.prange(pixels.shape[0]):
        march_ray(pixels[i, 1], pixels[i, 0], vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs)


def pixel_caster(caster: RayCaster, camera: Camera, size: int) -> Callable[[np.ndarray], None]:
    """A function casting the rays of the (N, 2) (row, column) pixels given, as ``caster.render`` casts them."""
    out = np.empty_like(caster.render(camera, size).data)
    cam = caster._camera_array(camera, size, size, (0.0, 0.0))
    params, tables = caster._params(0, False), caster.tables
    no_slabs = np.empty((1, 1, 1, SLAB_CHANNELS), np.float32)

    def cast(pixels: np.ndarray) -> None:
        _cast_pixels(pixels, caster.volume.array, caster._empty, tables.rgba, tables.gradient_opacity, cam,
                     caster._w2i, caster._grad_w, params, np.eye(4), out, no_slabs)
    return cast


def median_ms(jobs: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median ms of each job, run interleaved ``repeats`` times after one untimed call."""
    times: dict[str, list[float]] = {name: [] for name in jobs}
    for job in jobs.values():
        job()
    for _ in range(repeats):
        for name, job in jobs.items():
            started = time.perf_counter()
            job()
            times[name].append(1000.0 * (time.perf_counter() - started))
    return {name: statistics.median(ms) for name, ms in times.items()}


def top_pixels(rank: np.ndarray, fraction: float) -> np.ndarray:
    """(N, 2) (row, column) of the ``fraction`` of pixels with the highest ``rank``, in row order."""
    flat = np.sort(np.argsort(rank.ravel())[::-1][: int(fraction * rank.size)])
    return np.ascontiguousarray(np.stack(np.unravel_index(flat, rank.shape), axis=1))


def _range3x3(image: np.ndarray) -> np.ndarray:
    """Max minus min over each pixel's 3x3 neighbourhood (edges repeated)."""
    padded = np.pad(image, 1, mode="edge")
    h, w = image.shape
    windows = np.stack([padded[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)])
    return windows.max(axis=0) - windows.min(axis=0)


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.set_defaults(frames=9, sizes="512")
    parser.add_argument("--fractions", default="0.05,0.1,0.2,0.3")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    fractions = [float(f) for f in args.fractions.split(",")]
    camera = cameras[-1]
    print(f"{scene.label}, {args.degrees:g}° per frame, frame {len(cameras)} of the orbit\n")
    print("| output | method | share of a native frame's time | PSNR dB |\n|---|---|---:|---:|")
    for size in (int(s) for s in args.sizes.split(",")):
        truth = render_supersampled(caster, camera, size, size, spp=16, seed=10**6)
        native = caster.render(camera, size).color.copy()
        cast = pixel_caster(caster, camera, size)
        jobs: dict[str, Callable[[], object]] = {"native": lambda size=size: caster.render(camera, size)}
        scores = {"native": psnr_ssim(native, truth, channel_axis=-1)[0]}
        extra: dict[str, float] = {}  # ms measured apart: XS's median frame (LR render + upscaling) on the orbit
        for f in (2, 3, 4):
            lr = caster.render(camera, size // f).color
            jobs[f"1/{f} size + bilinear"] = lambda f=f, size=size: resize_bilinear(
                caster.render(camera, size // f).color, size, size)
            scores[f"1/{f} size + bilinear"] = psnr_ssim(resize_bilinear(lr, size, size), truth, channel_axis=-1)[0]
        for scale in (int(s) for s in args.scales.split(",")):
            pipeline = Pipeline(scene.volume, scene.transfer_function, scale=scale, variant="XS", size=(size, size),
                                threads=2)
            totals = []
            for c in cameras:
                image = pipeline.render(c)
                totals.append(pipeline.last_timings["total_ms"])
            xs_ms = statistics.median(totals[WARMUP:])
            luma = pipeline.last_low_resolution.color @ LUMA
            contrast = np.repeat(np.repeat(_range3x3(luma), scale, 0), scale, 1)
            error = np.square(image - truth).sum(axis=-1)
            scores[f"XS {scale}x"] = psnr_ssim(image, truth, channel_axis=-1)[0]
            extra[f"XS {scale}x"] = xs_ms
            for fraction in fractions:
                for rank_name, rank in (("contrast", contrast), ("oracle", error)):
                    pixels = top_pixels(rank, fraction)
                    refined = image.reshape(-1, 3).copy()
                    flat = pixels[:, 0] * size + pixels[:, 1]
                    refined[flat] = native.reshape(-1, 3)[flat]
                    name = f"XS {scale}x + {fraction:g} of pixels re-cast ({rank_name})"
                    scores[name] = psnr_ssim(refined.reshape(image.shape), truth, channel_axis=-1)[0]
                    jobs[name] = lambda pixels=pixels, cast=cast: cast(pixels)
                    extra[name] = xs_ms
        ms = median_ms(jobs, args.repeats)
        for name, psnr in scores.items():
            share = (ms.get(name, 0.0) + extra.get(name, 0.0)) / ms["native"]
            print(f"| {size}² | {name} | {share:.2f} | {psnr:.2f} |", flush=True)


if __name__ == "__main__":
    main()
