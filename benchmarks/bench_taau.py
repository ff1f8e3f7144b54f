"""Milliseconds per call of the TAAU kernel, on rendered orbit frames, optionally side by side with an earlier commit's.

    python benchmarks/bench_taau.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--sizes 512,1024] [--scales 2,4]
                                    [--degrees 2] [--frames 12] [--passes 3] [--slabs K] [--against COMMIT]

The LR frames of each output size and scale are rendered once, as ``volsr bench`` renders TAAU's (Halton
jitter, motion vectors to the previous camera, the reprojected point's depth, the view's rotation, the
frame's pixels per voxel; ray starts jittered), then fed ``--passes`` times through
``TemporalUpsampler`` (history reset before each pass). With ``--against COMMIT`` the
``volsr_core/temporal/taau.py`` of that commit (``git show``) runs too, interleaved call by call with
the current one (which goes first alternating from frame to frame) so that machine noise hits both alike;
the table gives the median ms per call of each (the calls after the first two frames of a pass, which have a
history), their ratio and the largest difference between their outputs. TAAU runs without its side outputs, as
``volsr bench``'s TAAU and variant XS run it (``--side-outputs``: with them, as before 2026-12-02). ``--slabs K``
times the layered TAAU instead (``LayeredUpsampler``, ``volsr_core/temporal/layered.py``) on frames rendered in K
depth slabs, as XS 4x runs.
``--volume`` is a ``volsr bench`` volume spec (``../shared/data/volumes`` is searched for a bare file name) or
``phantom``.
"""
from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType

import numpy as np

from volsr_core.apps.bench.scenes import BenchVolume, load_bench_volume
from volsr_core.render import RayCaster
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.temporal import halton_jitter, jitter_phases, layered
from volsr_core.temporal import taau as current
from volsr_core.temporal.taau import view_rotation

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "volumes"
KERNEL = "volsr_core/temporal/taau.py"
LAYERED_KERNEL = "volsr_core/temporal/layered.py"
HISTORY_FRAMES = 2  # calls before these have no (or a one-frame) history: not timed


def module_at(commit: str, folder: Path, kernel: str = KERNEL) -> ModuleType:
    """The module ``kernel`` (a path in the repository; by default TAAU's) as it was at ``commit``, imported
    from a copy in ``folder``."""
    source = subprocess.run(["git", "-C", str(REPO), "show", f"{commit}:{kernel}"], check=True,
                            capture_output=True, text=True).stdout
    path = folder / f"{Path(kernel).stem}_{commit.replace('/', '_')}.py"
    path.write_text(source, encoding="utf-8")
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = module
    spec.loader.exec_module(module)
    return module


def lr_frames(caster: RayCaster, cameras: list, size: int, scale: int, slabs: int = 0) -> list[tuple]:
    """TAAU's arguments for each camera: colour, motion, jitter, depth, rotation, pixels per voxel; with ``slabs``
    K the layered TAAU's: the frame's K depth slabs, jitter, background, rotation, pixels per voxel."""
    frames, previous = [], None
    for t, camera in enumerate(cameras):
        lr = caster.render(camera, size // scale, size // scale, jitter=halton_jitter(t, jitter_phases(scale)),
                           previous_camera=previous, seed=t, slabs=slabs)
        rotation = view_rotation(camera, previous)
        if slabs:
            frames.append((lr.slabs.copy(), lr.jitter, caster.background, rotation, lr.pixels_per_voxel))
        else:
            frames.append((lr.color.copy(), lr.motion.copy(), lr.jitter, lr.motion_depth.copy(), rotation,
                           lr.pixels_per_voxel))
        previous = camera
    return frames


def time_side_by_side(modules: list[ModuleType], frames: list[tuple], scale: int, passes: int, slabs: int = 0,
                      side_outputs: bool = False):
    """Median ms per call of each module's ``TemporalUpsampler`` (``side_outputs`` as given; with ``slabs``:
    ``LayeredUpsampler``), interleaved call by call, the order rotating from frame to frame, and the largest output
    difference."""
    upsamplers = [m.LayeredUpsampler(scale) if slabs else m.TemporalUpsampler(scale, side_outputs=side_outputs)
                  for m in modules]
    times: list[list[float]] = [[] for _ in modules]
    difference = 0.0
    for _ in range(passes):
        for upsampler in upsamplers:
            upsampler.reset()
        for t, args in enumerate(frames):
            outputs = [None] * len(upsamplers)
            for i in range(len(upsamplers)):
                k = (t + i) % len(upsamplers)
                started = time.perf_counter()
                outputs[k] = upsamplers[k](*args)
                if t >= HISTORY_FRAMES:
                    times[k].append(1000.0 * (time.perf_counter() - started))
            difference = max([difference] + [float(np.abs(o - outputs[0]).max()) for o in outputs[1:]])
    return [statistics.median(ms) for ms in times], difference


def table_header(columns: str, against: str | None) -> str:
    """The markdown header and rule of a side-by-side table: ``columns``, then ``against``'s ms, the ratio and the
    largest difference when there is a second kernel."""
    header = columns + (f" | {against} ms | ratio | max difference |" if against else " |")
    return header + "\n" + "|---" * (header.count("|") - 1) + "|"


def table_row(cells: str, ms: list[float], difference: float) -> str:
    """One row of :func:`table_header`'s table: ``cells``, then each kernel's median ``ms`` (current first), their
    ratio and ``difference`` when there are two."""
    row = f"{cells} | {ms[0]:.2f}"
    if len(ms) > 1:
        row += f" | {ms[1]:.2f} | {ms[0] / ms[1]:.2f} | {difference:.1e}"
    return row + " |"


def interleaved(methods: dict, cameras: list, truth: dict, warmup: int) -> dict:
    """Every method of ``methods`` (key -> a ``runtime.methods.Method``) on every camera, interleaved frame by frame
    (the order rotating per frame, as ``volsr bench`` runs them): key -> (median ms per frame, mean PSNR against
    ``truth`` (frame -> image) over the frames from ``warmup`` on)."""
    from volsr_core.sr.metrics import psnr_ssim

    keys = list(methods)
    ms: dict = {key: [] for key in keys}
    psnr: dict = {key: [] for key in keys}
    for t, camera in enumerate(cameras):
        first = t % len(keys)
        for key in keys[first:] + keys[:first]:
            frame = methods[key](camera)
            if t >= warmup:
                ms[key].append(frame.ms_total)
                psnr[key].append(psnr_ssim(frame.image, truth[t], channel_axis=-1)[0])
    return {key: (statistics.median(ms[key]), float(np.mean(psnr[key]))) for key in keys}


def orbit_parser(description: str) -> argparse.ArgumentParser:
    """The options a side-by-side kernel benchmark shares: the volume, sizes, scales, orbit and ``--against``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--volume", default="CT_AVM.nii.gz:CT-AAA:0,446")
    parser.add_argument("--sizes", default="512,1024")
    parser.add_argument("--scales", default="2,4")
    parser.add_argument("--degrees", type=float, default=2.0)
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--start", type=float, default=0.0, help="the orbit's first view this many degrees round "
                        "from the anterior one (a multiple of --degrees)")
    parser.add_argument("--against", metavar="COMMIT")
    return parser


def orbit_scene(args: argparse.Namespace) -> tuple[BenchVolume, RayCaster, list]:
    """The bench volume of ``args.volume`` (a bare file name is looked for in ``../shared/data/volumes``), its
    ray caster (ray starts jittered, as ``volsr bench`` renders) and the orbit's cameras, from ``args.start`` degrees
    round (0: the bench's anterior start)."""
    spec = args.volume if args.volume.startswith("phantom") or Path(args.volume.split(":")[0]).exists() \
        else str(DATA / args.volume)
    scene = load_bench_volume(spec)
    caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
    skipped = round(args.start / args.degrees)
    return scene, caster, orbit_around(caster.visible_bounds(), skipped + args.frames, args.degrees)[skipped:]


def main() -> None:
    parser = orbit_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--passes", type=int, default=3)
    parser.add_argument("--slabs", type=int, default=0, help="time the layered TAAU on K depth slabs (0: TAAU)")
    parser.add_argument("--side-outputs", action="store_true", help="TAAU with its side outputs (last_aux)")
    args = parser.parse_args()
    scene, caster, cameras = orbit_scene(args)
    kernel, module = (LAYERED_KERNEL, layered) if args.slabs else (KERNEL, current)
    with tempfile.TemporaryDirectory() as folder:
        modules = [module] + ([module_at(args.against, Path(folder), kernel)] if args.against else [])
        outputs = "" if args.slabs else f", {'with' if args.side_outputs else 'without'} side outputs"
        print(f"{scene.label}, {args.frames} frames of {args.degrees:g}°, {args.passes} passes{outputs}\n")
        print(table_header(f"| output | scale | {'layered TAAU' if args.slabs else 'TAAU'} ms", args.against))
        for size in (int(s) for s in args.sizes.split(",")):
            for scale in (int(s) for s in args.scales.split(",")):
                frames = lr_frames(caster, cameras, size, scale, args.slabs)
                ms, difference = time_side_by_side(modules, frames, scale, args.passes, args.slabs, args.side_outputs)
                print(table_row(f"| {size}² | {scale}x", ms, difference), flush=True)


if __name__ == "__main__":
    main()
