"""VolSR in ParaView's pvpython: show a volume in a ParaView render view, orbit it, upscale every frame.

    xvfb-run -a pvpython scripts/volsr_paraview.py [--venv .venv-paraview] INPUT --preset CT-Bone --orbit 8 \\
        --size 256 --scale 2 --out DIR [--model FILE] [--save-view]

INPUT is what ``volsr render`` reads (a DICOM folder or a file in it, .nrrd/.nhdr, .nii[.gz], .mha/.mhd, .vti;
none: the synthetic phantom), read with VolSR's readers (LPS millimetres) and handed to ParaView as a
vtkImageData. For each frame the ParaView view renders first, then VolSR renders with the view's camera and the
display's transfer function at 1/scale of the view and upscales. Written to DIR: frame_NNNN.png (VolSR),
paraview_NNNN.png (ParaView's own frame, --save-view), side_by_side_NNNN.png (both, --side-by-side),
cameras.json (the view's cameras, a VolSR camera-path file), transfer_function.json (what the display held),
summary.json, and volsr.mp4 when imageio-ffmpeg is installed (--video FILE elsewhere, --no-video for none).

pvpython (ParaView 5.11) runs Debian's Python 3.11; VolSR and onnxruntime come from the venv ``make
paraview-env`` builds: ``--venv DIR`` (this script's option: ParaView 5.11's pvpython has none), else
$VOLSR_PARAVIEW_VENV, else .venv-paraview beside this repository. See docs/paraview.md.
Exit status: 0 done, 2 bad input or arguments (one line on stderr).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def bootstrap(argv: list[str]) -> list[str]:
    """Make VolSR importable: this repository on sys.path, then the venv's packages in front (paraview_venv)."""
    argv = list(argv)
    venv = None
    for i, arg in enumerate(argv):
        if arg == "--venv" and i + 1 < len(argv):
            venv = argv[i + 1]
            del argv[i:i + 2]
            break
        if arg.startswith("--venv="):
            venv = arg.split("=", 1)[1]
            del argv[i]
            break
    if (REPO / "volsr_core").is_dir() and str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    from volsr_core.hosts.paraview_venv import activate, find_venv

    found = find_venv(venv, near=REPO)
    if found is not None:
        try:
            activate(found)
        except RuntimeError as err:
            print(f"volsr_paraview: error: {err}", file=sys.stderr)
            raise SystemExit(2) from None
    return argv


def build_parser() -> argparse.ArgumentParser:
    from volsr_core.apps.options import add_volume_arguments, parse_range, parse_size

    p = argparse.ArgumentParser(prog="pvpython scripts/volsr_paraview.py", description=__doc__.split("\n\n")[0],
                                epilog="--venv DIR (before or after the other options): the venv holding VolSR "
                                "and onnxruntime for this pvpython (default: $VOLSR_PARAVIEW_VENV or .venv-paraview)")
    add_volume_arguments(p)
    p.add_argument("--preset", help="shipped preset (default CT-Bone; CT-Phantom for the phantom)")
    p.add_argument("--tf", metavar="FILE", help="transfer function file (VolSR JSON, Slicer presets.xml, .vp)")
    p.add_argument("--tf-name", metavar="NAME", help="the preset to take from --tf")
    p.add_argument("--range", type=parse_range, default="auto",
                   help="auto (default), none, or LO,HI: where the preset's design range goes on the volume's values")
    p.add_argument("--orbit", type=int, default=24, metavar="N", help="frames of the orbit (default 24)")
    p.add_argument("--degrees", type=float, default=360.0, help="degrees the orbit turns (default 360)")
    p.add_argument("--elevation", type=float, default=0.0, help="elevation of the orbit in degrees (default 0)")
    p.add_argument("--size", type=parse_size, default=(512, 512), metavar="W[xH]",
                   help="view and output size in pixels (default 512)")
    p.add_argument("--scale", type=int, help="upscaling factor; VolSR renders at 1/scale (default 2; with --model, "
                   "the model's)")
    p.add_argument("--model", metavar="FILE", help=".onnx or .pt model (default: the shipped model of --variant)")
    p.add_argument("--variant", choices=["XS", "S", "M", "L"],
                   help="shipped model variant (default: the smallest shipped at --scale, XS at 2x)")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"], help="ray caster and network device")
    p.add_argument("--threads", type=int, help="onnxruntime intra-op threads (default: its own choice)")
    p.add_argument("--out", default="out/paraview", metavar="DIR", help="output folder (default out/paraview)")
    p.add_argument("--video", metavar="FILE", help="MP4 path (default DIR/volsr.mp4 when imageio-ffmpeg is installed)")
    p.add_argument("--no-video", action="store_true", help="write no MP4")
    p.add_argument("--fps", type=float, default=24.0, help="MP4 frames per second (default 24)")
    p.add_argument("--save-view", action="store_true", help="also write ParaView's own frames, paraview_NNNN.png")
    p.add_argument("--side-by-side", action="store_true",
                   help="also write side_by_side_NNNN.png: ParaView's frame and VolSR's, labelled")
    return p


def _video_path(args: argparse.Namespace) -> Path | None:
    if args.no_video:
        return None
    if args.video:
        return Path(args.video)
    try:
        import imageio  # noqa: F401
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        return None
    return Path(args.out) / "volsr.mp4"


def main(argv: list[str]) -> int:
    argv = bootstrap(argv)
    from volsr_core.errors import VolSRError

    args = build_parser().parse_args(argv)
    if args.orbit < 1 or (args.scale is not None and args.scale < 1):
        print("volsr_paraview: error: --orbit and --scale must be at least 1", file=sys.stderr)
        return 2
    try:
        from volsr_core.apps.options import load_volume_argument
        from volsr_core.hosts.paraview import orbit_and_upscale
        from volsr_core.scene.presets import choose_transfer_function

        volume = load_volume_argument(args)
        tf = choose_transfer_function(volume, args.preset, args.tf, args.tf_name, args.range)
        if args.model and not Path(args.model).is_file():
            raise VolSRError(f"{args.model}: no such model file")
        summary = orbit_and_upscale(volume, tf, args.out, frames=args.orbit, degrees=args.degrees,
                                    elevation=args.elevation, size=args.size, scale=args.scale,
                                    model=Path(args.model) if args.model else None, variant=args.variant,
                                    device=args.device, threads=args.threads, video=_video_path(args),
                                    fps=args.fps, save_view=args.save_view, side_by_side=args.side_by_side)
    except VolSRError as err:
        print(f"volsr_paraview: error: {err}", file=sys.stderr)
        return 2
    ms = summary["median_ms"]
    print(f"wrote {summary['frames']} frames of {args.size[0]}x{args.size[1]} ({args.scale}x from "
          f"{summary['low_resolution_size'][0]}x{summary['low_resolution_size'][1]}) to {args.out}; median ms per "
          f"frame: ParaView {ms['view_ms']:.0f}, VolSR render {ms['render_ms']:.0f}, network {ms['network_ms']:.0f}")
    return 0


if __name__ == "__main__":
    status = main(sys.argv[1:])
    if status:
        # sys.exit() in ParaView 5.11's pvpython after a view exists crashes (SIGSEGV) in C++ teardown;
        # an error status leaves at once, success falls off the end (pvpython's own, clean finalisation)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
