"""Command-line options shared by ``volsr`` and the pvpython script (scripts/volsr_paraview.py): numbers,
sizes, colours, ranges, the volume argument, and the output paths checked before any work starts.

argparse ``type=`` functions raise ``ArgumentTypeError`` (argparse prints ``volsr CMD: error: argument
--x: <problem>`` on one line and exits 2); the checks that need a loaded volume or the file system raise
:class:`~volsr_core.errors.InputError` / :class:`~volsr_core.errors.OutputError` (one line, exit 2).
"""
from __future__ import annotations

import argparse
import math
import os
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np

from volsr_core.errors import InputError, OutputError, write_error
from volsr_core.scene.presets import parse_placement

MAX_SIDE = 8192  # pixels per side of an image (8K): an 8192^2 frame's feature buffers alone take 4 GiB
MAX_SAMPLES_PER_VOXEL = 64  # the finest --sample-distance: 1/64 of the smallest voxel spacing (default: 1/2)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".gif", ".webp")
VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".webm")


# -- numbers ----------------------------------------------------------------------------------------
def _interval(low: float | None, high: float | None, low_open: bool) -> str:
    """'in [0, 1]', 'in (0, 1]', '>= 1', '> 0' or '' for the bounds of a number."""
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{low:g}, {high:g}]"
    if low is not None:
        return f"{'>' if low_open else '>='} {low:g}"
    return ""


def number(unit: str = "", low: float | None = None, high: float | None = None, *, low_open: bool = False,
           integer: bool = False) -> Callable[[str], float | int]:
    """An argparse type: a finite number (an integer with ``integer``) in [low, high] (``low_open``:
    above ``low``), the problem and the ``unit`` in the message otherwise."""
    kind = "an integer" if integer else "a finite number"
    expected = " ".join(part for part in (kind, f"of {unit}" if unit else "", _interval(low, high, low_open)) if part)

    def parse(text: str) -> float | int:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            value = math.nan
        if (not math.isfinite(value) or (low is not None and (value <= low if low_open else value < low))
                or (high is not None and value > high)):
            raise argparse.ArgumentTypeError(f"must be {expected}, got {text!r}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


def parse_size(text: str) -> tuple[int, int]:
    """'512' -> (512, 512); '640x480' -> (640, 480) as (width, height); sides of 1 to MAX_SIDE pixels."""
    try:
        parts = [int(p) for p in text.lower().split("x")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be W or WxH in pixels, got {text!r}") from None
    if len(parts) == 1:
        parts *= 2
    if len(parts) != 2 or min(parts) < 1 or max(parts) > MAX_SIDE:
        raise argparse.ArgumentTypeError(f"size must be W or WxH with sides of 1 to {MAX_SIDE} pixels, got {text!r}")
    return parts[0], parts[1]


def parse_rgb(text: str) -> tuple[float, float, float]:
    """'R,G,B' -> three floats, each in [0, 1] (a colour)."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(0.0 <= v <= 1.0 for v in values):  # NaN fails the comparison too
        raise argparse.ArgumentTypeError(f"must be R,G,B: three numbers in [0, 1], got {text!r}")
    return values


MAX_SLABS = 8  # depth slabs a command line may ask for: the render and the history grow with each
MAX_STRETCH = 8  # the bicubic stretch after the model a command line may ask for


def parse_stretch(text: str) -> int | str:
    """'auto' -> "auto" (chosen by the view and how fast it turns: :class:`~volsr_core.runtime.pipeline.Pipeline`);
    an integer in 1..MAX_STRETCH -> itself."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= MAX_STRETCH:
        raise argparse.ArgumentTypeError(f"must be auto or an integer in [1, {MAX_STRETCH}], got {text!r}")
    return value


def parse_slabs(text: str) -> int | None:
    """'auto' -> None (the model's own depth slabs); an integer in 0..MAX_SLABS -> itself."""
    if text.strip().lower() == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_SLABS:
        raise argparse.ArgumentTypeError(f"must be auto or an integer in [0, {MAX_SLABS}], got {text!r}")
    return value


def parse_range(text: str) -> tuple[float, float] | str:
    """'auto', 'none' or 'LO,HI' (:func:`~volsr_core.scene.presets.parse_placement`), for argparse."""
    try:
        return parse_placement(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def check_sample_distance(value: float | None, volume) -> None:
    """``--sample-distance`` (mm, already positive and finite) against the volume it steps through:
    at most MAX_SAMPLES_PER_VOXEL samples per voxel, and no longer than the volume's diagonal."""
    if value is None:
        return
    spacing = min(volume.spacing)
    finest = spacing / MAX_SAMPLES_PER_VOXEL
    diagonal = float(np.linalg.norm(np.ptp(volume.corners, axis=0)))
    if value < finest:
        raise InputError("--sample-distance", f"{value:g} mm takes more than {MAX_SAMPLES_PER_VOXEL} samples per "
                         f"voxel of {spacing:.4g} mm; give at least {finest:.3g} mm (default {spacing / 2:.4g} mm)")
    if value > diagonal:
        raise InputError("--sample-distance", f"{value:g} mm is longer than the volume's diagonal ({diagonal:.4g} mm)")


# -- the volume -------------------------------------------------------------------------------------
def add_volume_arguments(p: argparse.ArgumentParser) -> None:
    """The positional volume (none: the phantom), ``--series`` and ``--resample``."""
    p.add_argument("volume", nargs="?", help="DICOM folder (or a file in it), .nrrd, .nii[.gz], .mha/.mhd or .vti; "
                   "omitted: the built-in synthetic CT phantom")
    p.add_argument("--series", metavar="UID", help="DICOM SeriesInstanceUID to load (default: the series with most slices)")
    p.add_argument("--resample", action="store_true",
                   help="resample DICOM slices with missing or uneven gaps (a damaged file's slice too) to uniform "
                   "spacing instead of refusing; the slices it fills are printed")


def load_volume_argument(args: argparse.Namespace, report_repairs: bool = True):
    """The Volume the arguments name, or the phantom when none is given. What ``--resample`` repaired
    (damaged files skipped, slices filled) is printed to stderr unless not ``report_repairs``."""
    import sys

    from volsr_core.io import make_phantom
    from volsr_core.io.dicom import repair_notes
    from volsr_core.scene import Volume

    if args.volume is None:
        return Volume.from_record(make_phantom())
    volume = Volume.load(args.volume, series_uid=args.series, resample=args.resample)
    for note in repair_notes(volume.notes) if report_repairs else []:
        print(f"volsr: note: {args.volume}: {note}", file=sys.stderr)
    return volume


# -- outputs ----------------------------------------------------------------------------------------
def _nearest_folder(path: Path) -> Path:
    """The folder ``path`` is in or would be created in: ``path`` itself or its nearest existing parent;
    OutputError when that is a file."""
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(existing, "exists and is not a folder")
    return existing


def check_writable(folder: str | os.PathLike, name: str | os.PathLike | None = None) -> None:
    """OutputError naming ``name`` (default: ``folder``) unless files can be created in ``folder`` (or, when
    it does not exist yet, in the nearest existing folder above it): a probe file is created and deleted,
    which, unlike permission bits, also tells a read-only file system, and root from other users."""
    folder = Path(folder)
    try:
        fd, probe = tempfile.mkstemp(prefix=".volsr-write-check-", dir=_nearest_folder(folder))
    except OSError as err:
        raise write_error(folder if name is None else name, err) from None
    os.close(fd)
    os.unlink(probe)


def output_folder(path: str | os.PathLike, option: str = "--out", takes: str = "a folder") -> Path:
    """``path`` checked as an output folder before any work starts: not an existing file, not a name with an
    image or video extension (that names a file), writable. Nothing is created."""
    path = Path(path)
    if path.suffix.lower() in IMAGE_SUFFIXES + VIDEO_SUFFIXES and not path.is_dir():
        raise OutputError(path, f"names a {path.suffix} file; {option} takes {takes}")
    if path.exists() and not path.is_dir():
        raise OutputError(path, "exists and is not a folder")
    check_writable(path)
    return path


def output_file(path: str | os.PathLike) -> Path:
    """``path`` checked as an output file before any work starts: not an existing folder, its folder writable."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(path, "is a folder, not a file")
    check_writable(path.parent, name=path)
    return path
