"""The ``volsr`` command: one entry point, a subcommand per job.

Bad input, a bad option, or an output that cannot be written (no permission, read-only, full) prints one
line ``volsr: error: <file or option>: <problem>`` and exits with status 2; outputs are checked before any
work starts, and a write that fails later leaves no partial file.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from volsr_core.apps.options import (
    IMAGE_SUFFIXES, MAX_SAMPLES_PER_VOXEL, add_volume_arguments, check_sample_distance, load_volume_argument, number,
    output_file, output_folder, parse_range, parse_rgb, parse_size, parse_slabs, parse_stretch,
)
from volsr_core.errors import WRITE_ERRNOS, InputError, OutputError, VolSRError, require_extra, write_error
from volsr_core.runtime.models import DEFAULT_SCALE, default_variant
from volsr_core.sr.network_config import VARIANTS


# option types: finite numbers in range, with their units (apps/options.py)
DEGREES = number("degrees", -360, 360)
ELEVATION = number("degrees", -90, 90)
MILLIMETRES = number("mm", 0, low_open=True)
AT_LEAST_1 = number(low=1, integer=True)
AT_LEAST_0 = number(low=0, integer=True)


# -- volsr info -----------------------------------------------------------------------------------
def cmd_info(args: argparse.Namespace) -> int:
    volume = load_volume_argument(args, report_repairs=False)  # every note is printed below
    nx, ny, nz = volume.shape_xyz
    lo, hi = volume.value_range
    p_lo, p_hi = volume.percentiles()
    lines = [
        f"source      {volume.source}",
        f"modality    {volume.modality}" + (f" ({volume.units})" if volume.units else ""),
        f"size        {nx} x {ny} x {nz} voxels (x, y, z)",
        f"spacing     {volume.spacing[0]:.4g} x {volume.spacing[1]:.4g} x {volume.spacing[2]:.4g} mm",
        f"origin      ({volume.origin[0]:.4g}, {volume.origin[1]:.4g}, {volume.origin[2]:.4g}) mm, LPS",
        "direction   " + "  ".join("(" + ", ".join(f"{v:.4g}" for v in col) + ")" for col in volume.direction.T),
        f"extent      {np.ptp(volume.corners, axis=0).round(2).tolist()} mm",
        f"values      {lo:.6g} .. {hi:.6g} (0.5-99.5 percentiles {p_lo:.6g} .. {p_hi:.6g})",
        f"memory      {volume.array.nbytes / 2**20:.1f} MiB as float32",
    ]
    lines += [f"note        {note}" for note in volume.notes]
    for s in volume.series:  # DICOM: every series found, largest first; '*' marks the one loaded
        taken = "*" if volume.notes and s.series_uid in volume.notes[0] else " "
        lines.append(f"series {taken}   {s.series_uid}  {s.modality}  {s.n_files} files  {s.columns}x{s.rows}"
                     + (f"  {s.description}" if s.description else ""))
    print("\n".join(lines))
    return 0


# -- volsr render ---------------------------------------------------------------------------------
def cameras_for(args: argparse.Namespace, caster, n_default: int = 1) -> list:
    """The cameras ``--camera-path`` asks for, or ``--orbit``/``--degrees``/``--elevation``: an orbit
    framing what ``caster``'s transfer function shows of its volume (``RayCaster.visible_bounds``)."""
    from volsr_core.scene.camera_paths import orbit_around, read_camera_path

    if args.camera_path:
        return read_camera_path(args.camera_path)
    width, height = args.size
    return orbit_around(caster.visible_bounds(), args.orbit or n_default, args.degrees, args.elevation,
                        aspect=width / height)


def check_render_out(out: str) -> None:
    """``render --out`` before any work: one ``.png`` file (in a writable folder) or a writable folder. Render
    writes PNG only: a name with another image extension is refused, never taken as a folder's name."""
    target = Path(out)
    if target.suffix.lower() == ".png":
        output_file(target)
    elif target.suffix.lower() in IMAGE_SUFFIXES:
        raise OutputError(target, "volsr render writes PNG only; name a .png file or a folder")
    else:
        output_folder(target, takes="a folder or one .png file")


def output_paths(out: str, n_frames: int) -> tuple[list[Path], Path]:
    """PNG paths for the frames and the folder they go in; a single frame may be named '*.png'."""
    target = Path(out)
    if target.suffix.lower() == ".png":
        if n_frames != 1:
            raise InputError(out, f"names one PNG but {n_frames} frames will be rendered; give a folder")
        target.parent.mkdir(parents=True, exist_ok=True)
        return [target], target.parent
    if target.exists() and not target.is_dir():
        raise InputError(out, "exists and is not a folder")
    target.mkdir(parents=True, exist_ok=True)
    return [target / f"frame_{i:04d}.png" for i in range(n_frames)], target


def cmd_render(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from volsr_core.images import to_uint8, write_png
    from volsr_core.render import RayCaster
    from volsr_core.scene.presets import choose_transfer_function
    from volsr_core.temporal import TemporalAntiAliasing, halton_jitter, render_supersampled

    if args.taa and args.spp > 1:
        raise InputError(None, "--taa accumulates one jittered sample per frame; it does not combine with --spp")
    check_render_out(args.out)
    volume = load_volume_argument(args)
    check_sample_distance(args.sample_distance, volume)
    tf = choose_transfer_function(volume, args.preset, args.tf, args.tf_name, args.range)
    caster = RayCaster(volume, tf, sample_distance=args.sample_distance, device=args.device,
                       background=args.background)
    cameras = cameras_for(args, caster)
    width, height = args.size
    pngs, _ = output_paths(args.out, len(cameras))
    taa = TemporalAntiAliasing() if args.taa else None
    previous = None
    started = time.perf_counter()
    for i, (camera, png) in enumerate(zip(tqdm(cameras, desc="render", unit="frame", disable=len(cameras) < 2), pngs)):
        if args.spp == 1 or args.features:
            jitter = halton_jitter(i, 16) if taa else (0.0, 0.0)
            frame = caster.render(camera, width, height, jitter=jitter, previous_camera=previous, seed=i)
            if args.features:
                frame.save_npz(png.with_suffix(".npz"))
        if args.spp > 1:
            color = render_supersampled(caster, camera, width, height, spp=args.spp)
        else:
            color = taa(frame.color, frame.motion) if taa else frame.color
        write_png(png, to_uint8(color))
        previous = camera
    elapsed = time.perf_counter() - started
    mode = "TAA" if taa else f"{args.spp} spp"
    print(f"wrote {len(pngs)} frame(s) of {width}x{height} to {pngs[0] if len(pngs) == 1 else pngs[0].parent} "
          f"({1000 * elapsed / len(pngs):.0f} ms per frame, {mode}, transfer function {tf.name or 'from file'})")
    return 0


# -- volsr dataset --------------------------------------------------------------------------------
def cmd_dataset(args: argparse.Namespace) -> int:
    from volsr_core.dataset.config import read_config
    from volsr_core.dataset.videos import generate, parse_shard

    shard = parse_shard(args.shard)
    config = read_config(args.config)
    generate(config, output_folder(args.out), shard=shard, device=args.device)
    return 0


# -- volsr train ----------------------------------------------------------------------------------
def cmd_train(args: argparse.Namespace) -> int:
    for module in ("torch", "skimage"):
        require_extra(module, "volsr train")
    from volsr_core.sr.config import load_training_config
    from volsr_core.sr.least_squares import is_closed_form, train_base_filter
    from volsr_core.sr.training import Trainer, build_model

    config = load_training_config(args.config)
    model = build_model(config)
    if is_closed_form(model):  # variant XS: its filter has a closed-form least-squares fit
        result = train_base_filter(config, model)
        print(f"fitted the {model.config.base_kernel}x{model.config.base_kernel} base filter by least squares; "
              f"validation PSNR {result['best_psnr']:.2f} dB (best.pt in {config.out})")
        return 0
    trainer = Trainer(config)
    result = trainer.run()
    if trainer.rank == 0:
        best = (f"best validation PSNR {result['best_psnr']:.2f} dB (best.pt)" if result["best_psnr"] > float("-inf")
                else "no validation frames, so no best.pt")
        print(f"trained to step {result['step']}; {best}; checkpoints and log.csv in {config.out}")
    return 0


# -- volsr eval -----------------------------------------------------------------------------------
def cmd_eval(args: argparse.Namespace) -> int:
    for module in ("torch", "skimage", "matplotlib"):
        require_extra(module, "volsr eval")
    from volsr_core.apps.evaluate import OnnxNetwork, evaluate, write_report
    from volsr_core.sr.checkpoint import load_model

    output_folder(args.out)
    if Path(args.model).suffix == ".onnx":
        require_extra("onnxruntime", "volsr eval of an ONNX file")
        model = OnnxNetwork(args.model)
    else:
        model = load_model(args.model)
    results, showcase = evaluate(model, args.data, args.split)
    written = write_report(results, showcase, args.out)
    for name in results["methods"]:
        o = results["overall"][name]
        print(f"{name:18s} PSNR {o['psnr']:6.2f} dB   SSIM {o['ssim']:.4f}   temporal error {o['temporal']:.4f}")
    print(f"wrote {', '.join(p.name for p in written)} to {args.out}")
    return 0


# -- volsr upscale --------------------------------------------------------------------------------
AUTO_VARIANT_RULE = ("auto: the largest shipped variant at --scale (L > M > S > XS) whose network time for one frame "
                     "(measured at start-up: one warm-up, then the median of 3 runs on zeros) is at most "
                     "half the time of one LR render (1/--scale of --size) of the first camera of the first input, "
                     "so that it buys more than rendering more pixels in the same time would; where none is, the "
                     "same at --scale / 2 with the model's image stretched 2x, then / 4 stretched 4x, ... (unless "
                     "--stretch K is given: only K); the fastest timed when none fits")


def cmd_upscale(args: argparse.Namespace) -> int:
    from volsr_core.apps import upscale as batch
    from volsr_core.atomic import atomic_write, stale_parts
    from volsr_core.images import require_video
    from volsr_core.render import RayCaster
    from volsr_core.runtime.engines import open_engine
    from volsr_core.runtime.models import model_file_to_run
    from volsr_core.runtime.pipeline import Pipeline, auto_stretches
    from volsr_core.runtime.upscaler import takes_slabs
    from volsr_core.scene.camera_paths import read_camera_path
    from volsr_core.scene.presets import choose_transfer_function, get_preset, load_transfer_function

    out = output_folder(args.out)
    if args.video is not None:
        if Path(args.video).suffix.lower() == ".mp4":
            output_file(args.video)
        else:
            output_folder(args.video, "--video", takes="a .mp4 file or a folder")
        require_video()
    if args.reference_spp:
        require_extra("skimage", "--reference-spp (PSNR)")
    inputs = batch.expand_inputs(args.inputs)
    videos = batch.video_paths(args.video, [item.name for item in inputs])
    # what every input shares is checked once, before any rendering
    if args.camera_path:
        read_camera_path(args.camera_path)
    if args.tf:
        load_transfer_function(args.tf, name=args.tf_name)
    elif args.preset:
        get_preset(args.preset)
    # --scale is the whole factor from the rendered frame to --size; the model upscales --scale / --stretch of it
    model, variant, stretch = None, args.variant, args.stretch
    if stretch == "auto" and (args.model or args.budget_ms is not None or variant == "auto"):
        stretch = 1  # a model file upscales by its own scale; the frame budget and --variant auto choose their own
    elif stretch == "auto" and len(only := auto_stretches(args.scale, variant)) == 1:
        stretch = only[0]  # nothing to choose (8x: XS 4x + bicubic 2x; 16x: 4x)
    k = 1 if stretch == "auto" else stretch  # the stretch the model is checked for ("auto": the unstretched one)
    if args.scale is not None and args.scale % k:
        raise InputError("--stretch", f"{k} does not divide --scale {args.scale}")
    if args.scale is not None and args.scale // k < 2:
        raise InputError("--stretch", f"{k} leaves the model no upscaling at --scale {args.scale} (at most half)")
    if k > 1 and args.budget_ms is not None:
        raise InputError("--stretch", "--budget-ms chooses its own levels; give --stretch without it")
    scale = None if args.scale is None else args.scale // k  # the model's
    if args.model:
        if args.budget_ms is not None:
            raise InputError(args.model, "--budget-ms chooses among the shipped models; give it without --model")
        model = Path(args.model)
    else:
        scale = scale or DEFAULT_SCALE
        variant = variant or default_variant(scale)
        if variant != "auto" and args.budget_ms is None:
            model = model_file_to_run(variant, scale, args.device)
    if args.slabs and args.budget_ms is not None:
        raise InputError("--slabs", "--budget-ms runs each model with its own depth slabs; give --slabs without it")
    if model is not None:  # opened once, before any rendering: a missing extra or a bad file stops here
        engine = open_engine(model, device=args.device)
        model_scale = engine.config.scale
        if scale is not None and model_scale != scale:
            raise InputError(model, f"the model upscales {model_scale}x, not {scale}x (--scale"
                             + (f" {args.scale} / --stretch {k})" if k > 1 else ")"))
        if args.slabs and not takes_slabs(engine):
            raise InputError(model, f"takes no depth slabs (--slabs {args.slabs}): only a base-filter model on TAAU "
                             "(variant XS) or a network trained on it (taau_slabs) refines the layered TAAU")
        scale = model_scale

    for part in stale_parts(out / "summary.md"):  # left by a killed run
        part.unlink(missing_ok=True)
    summaries = []
    chose_stretch = False  # whether a pipeline could choose its stretch by the view (each input's line says which)
    for item in inputs:
        summary = batch.InputSummary(item.name, item.source or "phantom")
        summaries.append(summary)
        try:
            if item.error:
                raise InputError(item.source, item.error)
            volume = load_volume_argument(argparse.Namespace(volume=item.source, series=args.series,
                                                             resample=args.resample))
            tf = choose_transfer_function(volume, args.preset, args.tf, args.tf_name, args.range)
            check_sample_distance(args.sample_distance, volume)
            caster = RayCaster(volume, tf, sample_distance=args.sample_distance, background=args.background,
                               device=args.device)
            cameras = cameras_for(args, caster, n_default=24)
            if args.budget_ms is not None:  # the level per frame: the shipped models and native
                from volsr_core.runtime.budget import BudgetRenderer

                pipeline = BudgetRenderer(volume, tf, args.budget_ms, size=args.size, device=args.device,
                                          sample_distance=args.sample_distance, background=args.background)
            else:
                if model is None:  # --variant auto, decided once at the first input that loads: the model and stretch
                    whole = scale * k  # --stretch auto: the rule chooses the stretch too, else the one given
                    variant, model, k = batch.auto_variant(caster, cameras[0], args.size, whole, device=args.device,
                                                           stretches=None if args.stretch == "auto" else [k])
                    scale, stretch = whole // k, k
                # --stretch auto: the pipeline opens the shipped models it may choose between by itself
                pipeline = Pipeline(volume, tf, None if stretch == "auto" else model, scale=scale * k,
                                    size=args.size, variant=variant, device=args.device,
                                    sample_distance=args.sample_distance, background=args.background,
                                    slabs=args.slabs, stretch=stretch)
                chose_stretch = chose_stretch or pipeline.auto_stretch
            batch.upscale_cameras(pipeline, cameras, out / item.name, video=videos.get(item.name), fps=args.fps,
                                  side_by_side_panels=args.side_by_side, reference_spp=args.reference_spp,
                                  summary=summary, bilinear_scale=scale * k)
        except OutputError:  # the outputs cannot be written: the other inputs would fail the same way
            raise
        except Exception as err:  # one bad input must not stop the others; Ctrl-C still stops the batch
            summary.error = (str(err) if isinstance(err, VolSRError)
                             else f"{summary.source}: {type(err).__name__}: {' '.join(str(err).split())}")
            print(f"volsr: error: {summary.error}", file=sys.stderr)
    failed = sum(s.error is not None for s in summaries)
    whole = f"{scale * k}x" + (f" ({scale}x + bicubic {k}x)" if k > 1 else "")
    how = f"within a {args.budget_ms:g} ms frame budget" if args.budget_ms is not None else whole
    name = "-" if model is None else Path(str(model)).name + (" or stretched by the view and its turn (--stretch auto)"
                                                              if chose_stretch else "")
    print(f"upscaled {len(summaries) - failed} of {len(summaries)} input(s) {how}"
          + (f" with {name}" if model is not None else "") + (f", {failed} failed" if failed else ""))
    for s in summaries:
        print("  " + s.line())
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "summary.md", "w", encoding="utf-8") as fh:
        fh.write(batch.summary_markdown(summaries, whole, name, budget_ms=args.budget_ms))
    print(f"  summary: {out / 'summary.md'}")
    return 1 if failed else 0


def shipped_variants() -> str:
    """What resources/models ships, as --help says it: "M 4x, S 4x, S 8x"."""
    from volsr_core.runtime.models import shipped_models

    return ", ".join(f"{e['variant']} {e['scale']}x" for e in shipped_models()) or "none"


def add_upscale_parser(sub) -> None:
    up = sub.add_parser("upscale", help="render volumes at low resolution along a camera path and upscale them "
                        "with the SR network: PNG frames, MP4, side-by-side comparisons",
                        description="Render every INPUT at 1/--scale of --size along a camera path and upscale each "
                        "frame with the SR network: DIR/<input name>/frame_NNNN.png (and --video). Exit status 1 "
                        "when an input failed (the others still finish), 2 for bad arguments.")
    up.add_argument("inputs", nargs="*", metavar="INPUT",
                    help="DICOM folder (or a file in it), .nrrd, .nii[.gz], .mha/.mhd or .vti, or a .txt file listing "
                    "them one per line (# comments; relative paths from the list's folder); none: the phantom")
    up.add_argument("--series", metavar="UID",
                    help="DICOM SeriesInstanceUID to load (default: the series with most slices)")
    up.add_argument("--resample", action="store_true",
                    help="resample DICOM slices with missing or uneven gaps to uniform spacing instead of refusing")
    tf = up.add_mutually_exclusive_group()
    tf.add_argument("--preset", help="shipped preset name; default CT-Phantom for the phantom, CT-Bone otherwise")
    tf.add_argument("--tf", metavar="FILE", help="transfer function file: VolSR JSON, Slicer presets.xml or .vp")
    up.add_argument("--tf-name", metavar="NAME", help="which entry of a presets file --tf names")
    up.add_argument("--range", type=parse_range, default="auto", metavar="auto|none|LO,HI",
                    help="place the transfer function's design range (as for volsr render) [auto]")
    up.add_argument("--scale", type=number(low=2, high=16, integer=True),
                    help=f"upscaling factor [{DEFAULT_SCALE}; with --model, the model's]")
    up.add_argument("--size", type=parse_size, default=(1024, 1024), metavar="W[xH]", help="output size [1024]")
    path = up.add_mutually_exclusive_group()
    path.add_argument("--camera-path", metavar="FILE", help="camera path JSON (vtkCamera terms)")
    path.add_argument("--orbit", type=AT_LEAST_1, metavar="N", help="N frames orbiting the volume (360 degrees) [24]")
    up.add_argument("--degrees", type=DEGREES, metavar="DEG", help="orbit DEG degrees per frame instead of one full "
                    "turn over the frames (temporal methods need small steps, as when a user drags)")
    up.add_argument("--elevation", type=ELEVATION, default=0.0, metavar="DEG",
                    help="elevation of the orbit, degrees [0]")
    up.add_argument("--out", required=True, metavar="DIR", help="folder; frames go to DIR/<input name>/, whose "
                    "frame_NNNN.png files from an earlier run are deleted first (the folder never mixes runs; other "
                    "files stay), as are temporary files a killed run left")
    up.add_argument("--video", metavar="FILE.mp4|DIR", help="also write an H.264 MP4 (volsr[video]); several inputs: "
                    "<input name>.mp4 beside FILE.mp4 or in DIR")
    up.add_argument("--fps", type=number("frames per second", 0, 240, low_open=True), default=24.0,
                    help="frame rate of the MP4 [24]")
    up.add_argument("--side-by-side", action="store_true",
                    help="three labelled panels per frame: native full-size 1-spp render | bilinear upscaling of the "
                    "LR frame (VTK's ImageSampleDistance) | VolSR")
    up.add_argument("--reference-spp", type=AT_LEAST_0, default=0, metavar="N",
                    help="also render each frame natively with N jittered samples per pixel and print the PSNR of "
                    "VolSR and bilinear against it (slow) [0: off]")
    up.add_argument("--model", metavar="FILE", help="model file, .onnx (onnxruntime) or .pt (PyTorch); default: the "
                    "shipped model of --variant at --scale")
    up.add_argument("--variant", choices=VARIANTS + ("auto",),
                    help="shipped model size [the smallest shipped at --scale: XS at 2x, the model that pays off on a "
                    f"CPU (docs/performance.md)]; shipped: {shipped_variants()}; " + AUTO_VARIANT_RULE)
    up.add_argument("--budget-ms", type=number("ms per frame", 0, 60000, low_open=True), metavar="MS",
                    help="frame-budget mode: per moving frame, the finest of native full size, the shipped models, "
                    "TAAU alone and native renders at 1/2, 1/2.5, 1/3, 1/4, 1/5, 1/6 and 1/8 size stretched "
                    "bilinearly (by the size rendered; at a size, larger variant first, then TAAU, then bilinear) "
                    "whose measured time "
                    "fits MS (each timed on the first camera, then tracked frame by frame, as VTK's "
                    "AutoAdjustSampleDistances does; a model whose network costs more than half its LR render is "
                    "left out); a camera that holds still refines instead, one more full-size jittered sample per "
                    "frame (after N still frames: the native N-spp image); --scale then only sets the bilinear "
                    "panel's size")
    up.add_argument("--slabs", type=parse_slabs, default=None, metavar="auto|K",
                    help="render each frame in K depth slabs, each with its own TAAU history (the layered TAAU, "
                    "docs/temporal.md), for an XS model or a network trained on it to refine; 0: the TAAU on the "
                    "frame's colour [auto: the slabs the model was trained on (2 for the shipped XS 4x and U-Nets), "
                    "else 2 for XS at 4x and more, else 0; for XS 1 instead of 2 where few pixels show two slabs at "
                    "once, judged at each new history]")
    up.add_argument("--stretch", type=parse_stretch, default="auto", metavar="auto|K",
                    help="run the model at 1/K of --size and stretch its image by K to it (bicubic): --scale 4 "
                    "--stretch 2 renders at 1/4 size and runs the 2x model to 1/2 size, as near the curve of "
                    "rendering fewer pixels as the 4x model or nearer where a voxel spans several output pixels "
                    "(1024² on the benchmark volumes; docs/performance.md, 'Where the history lives') [auto: 2 at an "
                    "even --scale of 4 or more where a voxel of the view spans at least two output pixels (judged at "
                    "each new history) or while the view turns fast for its sampling (3.5 degrees a frame times its "
                    "pixels per voxel, until under 2.5), else 1; where the variant has no model at --scale, its "
                    "model of the largest scale below (--scale 8: XS 4x stretched 2x, 16: 4x); 1 with --model or "
                    "--budget-ms; with --variant auto that rule chooses]")
    up.add_argument("--device", choices=("cpu", "cuda"), default="cpu",
                    help="where rays are cast and the network runs; on cuda an XS model's TAAU and filter run there "
                    "too and one image per frame comes back [cpu]")
    up.add_argument("--sample-distance", type=MILLIMETRES, metavar="MM",
                    help=f"ray step, mm, down to 1/{MAX_SAMPLES_PER_VOXEL} of the smallest spacing "
                    "[half the smallest spacing]")
    up.add_argument("--background", type=parse_rgb, default=(0.0, 0.0, 0.0),
                    metavar="R,G,B", help="background colour in [0, 1] [0,0,0]")
    up.set_defaults(run=cmd_upscale)


# -- volsr bench ----------------------------------------------------------------------------------
def parse_int_list(text: str) -> list[int]:
    """'2,4,8' -> [2, 4, 8]: positive integers."""
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers >= 1, got {text!r}")
    return values


def cmd_bench(args: argparse.Namespace) -> int:
    from volsr_core.apps.bench import report, run

    out = output_folder(args.out)
    results = run.run_benchmark(
        args.volumes, args.size, frames=args.frames, degrees=args.degrees, warmup=args.warmup,
        reference_spp=args.reference_spp, spp=args.native_spp, factors=args.factors, scales=args.scales,
        stretches=args.stretch, variants=[v.strip().upper() for v in args.variants.split(",") if v.strip()],
        models_dir=args.models_dir, preset=args.preset, placement=args.range, threads=args.threads,
        device=args.device, vtk=args.vtk, timing_passes=args.timing_passes)
    written = report.write_outputs(results, out)
    for scene, targets in results["targets"].items():
        print(f"{scene}:")
        for line in report.target_lines(targets):
            print("  " + line.replace("**", ""))
    print(f"wrote {', '.join(p.name for p in written)} to {out}")
    return 0


def add_bench_parser(sub) -> None:
    b = sub.add_parser("bench", help="quality against time: native, native + bilinear, TAAU and VolSR side by side "
                       "(bench.json, bench.md, bench.png; docs/performance.md)",
                       description="For each volume, orbit the camera --frames frames of --degrees each and render "
                       "every frame with every method: native full size at each --spp; native at 1/factor size + "
                       "bilinear upscaling for each --factors (VTK's ImageSampleDistance); TAAU at each --scales; "
                       "VolSR (Pipeline, onnxruntime) for every model of --variants at --scales, and stretched by "
                       "--stretch to --scales. PSNR and SSIM "
                       "against a --reference-spp supersampled native rendering are averaged over the frames after "
                       "--warmup warm-up frames; ms per frame are medians over the same frames of --timing-passes "
                       "passes. Also checks the targets of docs/performance.md.")
    b.add_argument("volumes", nargs="*", metavar="VOLUME[:PRESET[:RANGE]]",
                   help="volume files as volsr render takes them, each optionally with its preset and range (auto, "
                   "none or LO,HI), e.g. CT_AVM.nii.gz:CT-AAA:0,446 LIDC2.mha:CT-Bone:0,255 bonsai.nii.gz:CT-Bone "
                   "(VOLUME::RANGE keeps the default preset); 'phantom' or none: the built-in phantom")
    b.add_argument("--preset", help="preset for volumes that name none; default CT-Phantom for the phantom, CT-Bone "
                   "otherwise")
    b.add_argument("--range", type=parse_range, default="auto", metavar="auto|none|LO,HI",
                   help="range for volumes that name none (as for volsr render) [auto]")
    b.add_argument("--size", type=parse_size, default=(512, 512), metavar="W[xH]",
                   help="output size; divisible by every --scales [512]")
    b.add_argument("--out", required=True, metavar="DIR", help="folder for bench.json, bench.md and bench.png")
    b.add_argument("--frames", type=AT_LEAST_1, default=12, metavar="N", help="frames of the camera orbit [12]")
    b.add_argument("--degrees", type=DEGREES, default=2.0, metavar="DEG", help="orbit step per frame, degrees [2]")
    b.add_argument("--warmup", type=AT_LEAST_0, default=4, metavar="N",
                   help="first frames left out of quality and time (history builds up, kernels compile) [4]")
    b.add_argument("--timing-passes", type=AT_LEAST_1, default=3, metavar="N",
                   help="passes over the orbit whose times count: the scored one and N - 1 more with fresh methods, "
                   "timed only (one pass's 8 frames decide no 0.5 dB margin at 1024² on a 2-core machine) [3]")
    b.add_argument("--reference-spp", type=AT_LEAST_1, default=16, metavar="N",
                   help="jittered samples per pixel of the ground truth [16]")
    b.add_argument("--spp", dest="native_spp", type=parse_int_list, default=[1, 2, 4], metavar="N,..",
                   help="samples per pixel of the native full-size renderings [1,2,4]")
    b.add_argument("--factors", type=parse_int_list, default=[2, 3, 4, 6, 8], metavar="F,..",
                   help="size reductions for native + bilinear [2,3,4,6,8]")
    b.add_argument("--scales", type=parse_int_list, default=[2, 4, 8], metavar="S,..",
                   help="upscaling factors of TAAU and the VolSR models [2,4,8]")
    b.add_argument("--stretch", type=parse_int_list, default=[2], metavar="K,..",
                   help="also every model whose scale times K is one of --scales, its image stretched by K "
                   "(bicubic: a point at that scale, VolSR XS 2x + bicubic 2x at 4x); 1 for none [2]")
    b.add_argument("--variants", default=",".join(VARIANTS), metavar="V,..",
                   help=f"VolSR model variants [{','.join(VARIANTS)}]")
    b.add_argument("--models-dir", metavar="DIR",
                   help="folder of .onnx models (export_onnx) to use instead of the shipped ones; scale and variant "
                   "come from each model's metadata")
    b.add_argument("--threads", type=AT_LEAST_1, default=2, metavar="N", help="onnxruntime intra-op threads [2]")
    b.add_argument("--device", choices=("cpu", "cuda"), default="cpu",
                   help="where rays are cast and the network runs; on cuda TAAU and XS models keep the frame on "
                   "the GPU [cpu]")
    b.add_argument("--vtk", choices=("gpu", "fixed_point"),
                   help="also VTK's own mapper at full size (vtkGPUVolumeRayCastMapper through EGL on the GPU, or "
                   "its CPU ray caster): the host's renderer, timed in the same run")
    b.set_defaults(run=cmd_bench)


# -- volsr warmup ---------------------------------------------------------------------------------
def cmd_warmup(args: argparse.Namespace) -> int:
    from volsr_core.runtime.warmup import compile_kernels

    started = time.perf_counter()
    timings = compile_kernels(progress=True)
    for name, seconds in timings:
        print(f"  {seconds:6.1f} s  {name}")
    print(f"VolSR's kernels are in numba's disk cache ({time.perf_counter() - started:.1f} s)")
    return 0


# -- entry point ----------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="volsr", description="Learned super-resolution for medical volume rendering.")
    sub = parser.add_subparsers(dest="command", required=True)

    info = sub.add_parser("info", help="geometry, value range and DICOM series of a volume")
    add_volume_arguments(info)
    info.set_defaults(run=cmd_info)

    render = sub.add_parser("render", help="ray-cast a volume to PNG frames (and .npz feature buffers)")
    add_volume_arguments(render)
    tf = render.add_mutually_exclusive_group()
    tf.add_argument("--preset", help="shipped preset name (see resources/presets); default CT-Phantom for the "
                    "phantom, CT-Bone otherwise")
    tf.add_argument("--tf", metavar="FILE", help="transfer function file: VolSR JSON, Slicer presets.xml or .vp")
    render.add_argument("--tf-name", metavar="NAME", help="which entry of a presets file --tf names")
    render.add_argument("--range", type=parse_range, default="auto", metavar="auto|none|LO,HI",
                        help="place the transfer function's design range on LO,HI; auto: on the volume's "
                        "0.5-99.5 percentiles unless the volume is in the preset's units (HU) [auto]")
    render.add_argument("--size", type=parse_size, default=(512, 512), metavar="W[xH]", help="image size [512]")
    path = render.add_mutually_exclusive_group()
    path.add_argument("--camera-path", metavar="FILE", help="camera path JSON (vtkCamera terms)")
    path.add_argument("--orbit", type=AT_LEAST_1, metavar="N",
                      help="N frames orbiting the volume (azimuth, 360 degrees)")
    render.add_argument("--degrees", type=DEGREES, metavar="DEG",
                        help="orbit DEG degrees per frame instead of one full turn over the frames")
    render.add_argument("--elevation", type=ELEVATION, default=0.0, metavar="DEG",
                        help="elevation of the default anterior view, degrees [0]")
    render.add_argument("--spp", type=AT_LEAST_1, default=1, metavar="N",
                        help="jittered samples per pixel (Halton 2,3) [1]")
    render.add_argument("--taa", action="store_true",
                        help="temporal anti-aliasing over the frames: one Halton-jittered ray per pixel and frame, "
                        "history reprojected with the motion vectors and clamped to the 3x3 neighbourhood")
    render.add_argument("--sample-distance", type=MILLIMETRES, metavar="MM",
                        help=f"ray step, mm, down to 1/{MAX_SAMPLES_PER_VOXEL} of the smallest spacing "
                        "[half the smallest spacing]")
    render.add_argument("--background", type=parse_rgb, default=(0.0, 0.0, 0.0),
                        metavar="R,G,B", help="background colour in [0, 1] [0,0,0]")
    render.add_argument("--device", choices=("cpu", "cuda"), default="cpu", help="where rays are cast [cpu]")
    render.add_argument("--out", required=True, metavar="DIR_OR_PNG", help="folder for frame_NNNN.png, or one .png "
                        "file (PNG only: another image extension is refused)")
    render.add_argument("--features", action="store_true",
                        help="also write frame_NNNN.npz with colour, alpha, depth, max-alpha RGBA, position, motion "
                        "(of the 1-spp pass)")
    render.set_defaults(run=cmd_render)

    dataset = sub.add_parser("dataset", help="render training videos: LR feature buffers at every scale + HR "
                             "ground truth (docs/dataset.md)")
    dataset.add_argument("config", help="dataset config, YAML (training/configs/dataset_default.yaml)")
    dataset.add_argument("--out", required=True, metavar="DIR", help="dataset folder; a run resumes what is there")
    dataset.add_argument("--shard", default="0/1", metavar="i/n",
                         help="render only the videos whose number %% n == i [0/1]")
    dataset.add_argument("--device", choices=("cpu", "cuda"), default="cpu", help="where rays are cast [cpu]")
    dataset.set_defaults(run=cmd_dataset)

    train = sub.add_parser("train", help="train the SR network (resumes from OUT/checkpoints/last.pt); "
                           "several processes: torchrun --nproc_per_node N -m volsr_core.cli train CONFIG")
    train.add_argument("config", help="training config, YAML (training/configs/*.yaml)")
    train.set_defaults(run=cmd_train)

    ev = sub.add_parser("eval", help="the network vs bilinear, bicubic and TAAU on a dataset split: JSON, "
                        "markdown table, plots, zoomed crops")
    ev.add_argument("model", help="model file (best.pt), training checkpoint, or ONNX file (run by onnxruntime on the "
                    "CPU, as hosts run it: an 8-bit one too)")
    ev.add_argument("--data", required=True, metavar="DIR", help="dataset folder (volsr dataset)")
    ev.add_argument("--split", default="test", choices=("train", "val", "test"), help="[test]")
    ev.add_argument("--out", default="out/eval", metavar="DIR", help="report folder [out/eval]")
    ev.set_defaults(run=cmd_eval)

    add_upscale_parser(sub)
    add_bench_parser(sub)

    warmup = sub.add_parser("warmup", help="compile VolSR's kernels into numba's disk cache, once after installing "
                            "(about a minute on 2 cores), so that no first frame waits for them",
                            description="Numba compiles each kernel at its first use and caches it on disk. This "
                            "runs every path a host or command takes (native rendering, VolSR XS at 2x, 4x and "
                            "stretched, a U-Net model) on a small phantom; with the cache filled it takes a fraction "
                            "of a second.")
    warmup.set_defaults(run=cmd_warmup)
    return parser


def os_error_line(err: OSError) -> str:
    """An OSError that reached the top as one line naming its file: a refused write in the words of
    :func:`~volsr_core.errors.write_error`, any other as the system says it."""
    if err.filename is not None and err.errno in WRITE_ERRNOS:
        return str(write_error(err.filename, err))
    reason = err.strerror or " ".join(str(err).split()) or type(err).__name__
    return reason if err.filename is None else f"{err.filename}: {reason}"


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except VolSRError as err:
        print(f"volsr: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # a file or folder the system refused (permission, read-only, full) outside atomic writes
        print(f"volsr: error: {os_error_line(err)}", file=sys.stderr)
        return 2
    except MemoryError:
        print("volsr: error: out of memory; try a smaller --size or a smaller volume", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("volsr: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
