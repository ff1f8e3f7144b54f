"""Command-line options shared by ``volsr`` and the pvpython script (scripts/volsr_paraview.py): sizes,
ranges, the volume argument. argparse ``type=`` functions raise ``ArgumentTypeError`` (argparse prints
it on one line and exits 2)."""
from __future__ import annotations

import argparse

from volsr_core.scene.presets import parse_placement


def parse_size(text: str) -> tuple[int, int]:
    """'512' -> (512, 512); '640x480' -> (640, 480) as (width, height)."""
    try:
        parts = [int(p) for p in text.lower().split("x")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be W or WxH in pixels, got {text!r}") from None
    if len(parts) == 1:
        parts *= 2
    if len(parts) != 2 or min(parts) < 1:
        raise argparse.ArgumentTypeError(f"size must be W or WxH with positive integers, got {text!r}")
    return parts[0], parts[1]


def parse_range(text: str) -> tuple[float, float] | str:
    """'auto', 'none' or 'LO,HI' (:func:`~volsr_core.scene.presets.parse_placement`), for argparse."""
    try:
        return parse_placement(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def add_volume_arguments(p: argparse.ArgumentParser) -> None:
    """The positional volume (none: the phantom), ``--series`` and ``--resample``."""
    p.add_argument("volume", nargs="?", help="DICOM folder (or a file in it), .nrrd, .nii[.gz], .mha/.mhd or .vti; "
                   "omitted: the built-in synthetic CT phantom")
    p.add_argument("--series", metavar="UID", help="DICOM SeriesInstanceUID to load (default: the series with most slices)")
    p.add_argument("--resample", action="store_true",
                   help="resample DICOM slices with missing or uneven gaps to uniform spacing instead of refusing")


def load_volume_argument(args: argparse.Namespace):
    """The Volume the arguments name, or the phantom when none is given."""
    from volsr_core.io import make_phantom
    from volsr_core.scene import Volume

    if args.volume is None:
        return Volume.from_record(make_phantom())
    return Volume.load(args.volume, series_uid=args.series, resample=args.resample)
