"""DICOM slice stacks: find the series in a folder, sort slices in space, stack them in LPS mm.

Geometry (DICOM PS3.3 C.7.6.2): a slice's pixel (row r, column c) lies at

    ImagePositionPatient + c * column_spacing * row_cosine + r * row_spacing * column_cosine

with ``ImageOrientationPatient = row_cosine + column_cosine`` and ``PixelSpacing =
[row_spacing, column_spacing]`` = [y, x] spacing. Slices are ordered by the projection of
their ImagePositionPatient on the slice normal ``row_cosine x column_cosine`` (never by file
name or InstanceNumber), so index k runs along +normal and the direction matrix is
``[row_cosine | column_cosine | normal]``, right-handed, as SimpleITK's series reader gives it.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pydicom
from pydicom.dataset import Dataset
from pydicom.multival import MultiValue

from volsr_core.errors import InputError
from volsr_core.io.record import SeriesInfo, VolumeRecord
from volsr_core.io.sniff import check_content, is_dicom_file

#: Relative deviation of a slice gap from the median gap that still counts as uniform.
GAP_TOLERANCE = 0.01
#: A gap at least this many median gaps wide has slices missing: resampling fills them.
FILLED_GAP = 1.5
#: MediaStorageSOPClassUID of a DICOMDIR: a DICOM file that rightly has no SeriesInstanceUID.
DICOMDIR_SOP_CLASS = "1.2.840.10008.1.3.10"
#: Notes of what ``resample`` repaired start with these (:func:`repair_notes`).
REPAIR_PREFIXES = ("resampled ", "skipped ")
_REQUIRED_TAGS = ("Rows", "Columns", "PixelSpacing", "ImagePositionPatient", "ImageOrientationPatient")


@dataclass(frozen=True)
class _Header:
    """One DICOM file's header (read without pixel data)."""

    path: Path
    ds: Dataset


@dataclass(frozen=True)
class _Slice:
    """The geometry tags of one single-frame image, checked and parsed."""

    path: Path
    ds: Dataset
    rows: int
    columns: int
    pixel_spacing: tuple[float, float]  # DICOM order: (row spacing = y, column spacing = x), mm
    position: np.ndarray  # ImagePositionPatient, LPS mm
    orientation: np.ndarray  # ImageOrientationPatient: row cosine (3), column cosine (3)


@dataclass(frozen=True)
class _Stack:
    """Slices of one series in spatial order, with the geometry they share."""

    slices: list[_Slice]
    positions: np.ndarray  # mm along the slice normal, increasing
    direction: np.ndarray  # columns: row cosine (x), column cosine (y), normal (z)
    pixel_spacing: tuple[float, float]  # (x, y) mm


def list_dicom_series(path: str | os.PathLike) -> list[SeriesInfo]:
    """The DICOM series in a folder (and its subfolders), or in the folder of a DICOM file.

    Largest series (most files) first. Raises InputError for a missing path, an empty folder,
    or a folder without DICOM files.
    """
    folder, _, recursive = _locate(Path(path))
    groups, _, damaged = _scan(folder, recursive, source=path)
    _refuse_damaged(damaged, resample_hint=False)
    return _series_infos(groups)


def repair_notes(notes: list[str]) -> list[str]:
    """The notes of a record that say what ``resample`` repaired: damaged files skipped, slices filled."""
    return [note for note in notes if note.startswith(REPAIR_PREFIXES)]


def read_dicom(path: str | os.PathLike, series_uid: str | None = None, resample: bool = False) -> VolumeRecord:
    """Read one DICOM series as a volume (float32 (z, y, x), LPS mm; HU for CT).

    ``path`` is a folder (searched with its subfolders) or one file of the series (its folder is
    searched, not recursively, and its own series is taken). Without ``series_uid`` the series
    with the most files is taken. Non-uniform slice spacing, and a damaged file (a header or
    pixel data cut short, a ``.dcm`` file without a DICOM header), raise InputError naming it
    unless ``resample`` is set, which skips damaged files and interpolates linearly to the median
    slice gap; the notes then say which files were skipped and which slices were filled
    (:func:`repair_notes`).
    """
    path = Path(path)
    folder, given_file, recursive = _locate(path)
    groups, ignored, damaged = _scan(folder, recursive, source=path)
    if not resample:
        _refuse_damaged(damaged, resample_hint=True)
    uid = _pick_series(path, groups, series_uid, given_file)
    stack = _sort_slices(path, uid, groups[uid])
    notes = [_series_note(uid, stack.slices)]
    notes += _other_series_notes(uid, groups)
    if ignored:
        notes.append(f"ignored {ignored} non-DICOM or non-image files in {folder}")
    slice_step, uneven = _slice_step(path, stack, resample)
    volume, rescale_note, units, unreadable = _read_pixels(stack.slices)
    notes.append(rescale_note)
    if unreadable:
        damaged += [(stack.slices[k].path, problem) for k, problem in unreadable]
        if not resample:
            _refuse_damaged(damaged, resample_hint=True)
        stack = _without(path, stack, [k for k, _ in unreadable])
        slice_step, uneven = _slice_step(path, stack, resample)
    if damaged:
        notes.append(f"skipped {len(damaged)} damaged file{'s' if len(damaged) != 1 else ''}: "
                     + "; ".join(f"{file.name} ({problem})" for file, problem in damaged))
    if uneven:
        gaps = np.diff(stack.positions)
        n_before = volume.shape[0]
        volume = _resample_slices(volume, stack.positions, slice_step)
        filled = _filled_slices(stack, slice_step)
        notes.append(
            f"resampled {n_before} unevenly spaced slices ({gaps.min():.3g}-{gaps.max():.3g} mm apart) to "
            f"{volume.shape[0]} slices {slice_step:.3g} mm apart (the median gap) by linear interpolation "
            "along the slice normal" + (f"; filled {'; '.join(filled)}" if filled else "")
        )
    first = stack.slices[0]
    return VolumeRecord(
        array=volume,
        spacing=(stack.pixel_spacing[0], stack.pixel_spacing[1], slice_step),
        origin=tuple(first.position),
        direction=stack.direction,
        modality=str(first.ds.get("Modality", "") or "OT"),
        units=units,
        source=str(path),
        series=_series_infos(groups),
        notes=notes,
    )


def _locate(path: Path) -> tuple[Path, Path | None, bool]:
    """(folder to search, the file given or None, search subfolders?) for a folder or DICOM file."""
    if not path.exists():
        raise InputError(path, "no such file or folder")
    if path.is_dir():
        return path, None, True
    check_content(path, "dicom")
    return path.parent, path, False


def _scan(folder: Path, recursive: bool,
          source: str | os.PathLike) -> tuple[dict[str, list[_Header]], int, list[tuple[Path, str]]]:
    """Headers of the DICOM image files under ``folder`` grouped by SeriesInstanceUID, the number of
    other files (not DICOM, or a DICOMDIR), and the damaged files with their problem: a header that
    does not parse, an image without SeriesInstanceUID (cut short), a ``.dcm`` file without the
    DICOM magic (cut within its first 132 bytes)."""
    files = _files_in(folder, recursive)
    if not files:
        raise InputError(source, "folder is empty" if not any(folder.iterdir()) else "folder holds no files")
    groups: dict[str, list[_Header]] = {}
    ignored = 0
    damaged: list[tuple[Path, str]] = []
    for file in files:
        if not is_dicom_file(file):
            if file.suffix.lower() == ".dcm":
                damaged.append((file, f"named .dcm but without a DICOM header ({file.stat().st_size} bytes; "
                                      "truncated?)"))
            else:
                ignored += 1
            continue
        try:
            ds = _read_header(file)
        except InputError as err:
            damaged.append((file, err.problem))
            continue
        uid = str(ds.get("SeriesInstanceUID", "") or "")
        if not uid:
            sop_class = str(getattr(ds, "file_meta", {}).get("MediaStorageSOPClassUID", "") or "")
            if sop_class == DICOMDIR_SOP_CLASS:
                ignored += 1
            else:
                damaged.append((file, "DICOM file without SeriesInstanceUID (a header cut short?)"))
            continue
        groups.setdefault(uid, []).append(_Header(file, ds))
    if not groups and damaged:
        _refuse_damaged(damaged, resample_hint=False)
    if not groups:
        example = os.path.relpath(files[0], folder)
        raise InputError(
            source,
            f"no DICOM image files found among {len(files)} files (e.g. {example}); "
            "DICOM files carry 'DICM' at byte 128",
        )
    return groups, ignored, damaged


def _refuse_damaged(damaged: list[tuple[Path, str]], resample_hint: bool) -> None:
    """InputError naming the first damaged file (and how many more there are), if any."""
    if not damaged:
        return
    file, problem = damaged[0]
    more = f" ({len(damaged) - 1} more damaged file{'s' if len(damaged) > 2 else ''})" if len(damaged) > 1 else ""
    hint = "; remove it, or pass resample=True (CLI --resample) to skip it and fill its slice" if resample_hint else ""
    raise InputError(file, f"{problem}{more}{hint}")


def _files_in(folder: Path, recursive: bool) -> list[Path]:
    """Regular files in ``folder`` (and its non-hidden subfolders when ``recursive``), sorted."""
    if not recursive:
        return sorted(p for p in folder.iterdir() if p.is_file())
    found: list[Path] = []
    for root, dirs, names in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        found += [Path(root, n) for n in sorted(names) if os.path.isfile(os.path.join(root, n))]
    return found


def _read_header(file: Path) -> Dataset:
    """Header of a DICOM file without its pixel data; a damaged header raises InputError."""
    try:
        return pydicom.dcmread(file, stop_before_pixels=True, force=False)
    except Exception as err:  # pydicom raises many types for damaged files
        raise InputError(file, f"cannot read the DICOM header: {_one_line(err)}") from None


def _series_infos(groups: dict[str, list[_Header]]) -> list[SeriesInfo]:
    """SeriesInfo of every series, most files first (ties by UID, for a stable order)."""
    infos = []
    for uid, headers in groups.items():
        ds = headers[0].ds
        infos.append(
            SeriesInfo(
                series_uid=uid,
                description=str(ds.get("SeriesDescription", "") or ""),
                modality=str(ds.get("Modality", "") or ""),
                n_files=len(headers),
                rows=int(ds.get("Rows", 0) or 0),
                columns=int(ds.get("Columns", 0) or 0),
            )
        )
    return sorted(infos, key=lambda info: (-info.n_files, info.series_uid))


def _pick_series(
    source: Path, groups: dict[str, list[_Header]], series_uid: str | None, given_file: Path | None
) -> str:
    """The UID to load: ``series_uid`` if given, else the given file's series, else the largest."""
    if series_uid is not None:
        if series_uid not in groups:
            available = ", ".join(f"{info.series_uid} ({info.n_files} files)" for info in _series_infos(groups))
            raise InputError(source, f"no series with SeriesInstanceUID {series_uid}; available: {available}")
        return series_uid
    if given_file is not None:
        for uid, headers in groups.items():
            if any(h.path == given_file for h in headers):
                return uid
        raise InputError(given_file, "DICOM file has no SeriesInstanceUID (a DICOMDIR or non-image object?)")
    return _series_infos(groups)[0].series_uid


def _series_note(uid: str, slices: list[_Slice]) -> str:
    description = str(slices[0].ds.get("SeriesDescription", "") or "")
    return (
        f"DICOM series {uid}" + (f" ('{description}')" if description else "")
        + f": {len(slices)} slices, ordered by ImagePositionPatient along the slice normal"
    )


def _other_series_notes(uid: str, groups: dict[str, list[_Header]]) -> list[str]:
    others = [info for info in _series_infos(groups) if info.series_uid != uid]
    if not others:
        return []
    listed = "; ".join(
        f"{info.series_uid} ({info.n_files} files" + (f", '{info.description}'" if info.description else "") + ")"
        for info in others
    )
    return [f"{len(others)} other series in the folder not loaded (choose with series_uid / --series): {listed}"]


def _sort_slices(source: Path, uid: str, headers: list[_Header]) -> _Stack:
    """Check that the slices share size, pixel spacing and orientation; order them along the normal."""
    slices = [_parse_slice(header) for header in headers]
    first = slices[0]
    for other in slices[1:]:
        if (other.rows, other.columns) != (first.rows, first.columns):
            raise InputError(
                source,
                f"mixed slice sizes in series {uid}: {first.path.name} is {first.columns}x{first.rows}, "
                f"{other.path.name} is {other.columns}x{other.rows} pixels",
            )
        if not np.allclose(other.orientation, first.orientation, atol=1e-4):
            raise InputError(
                source, f"mixed slice orientations in series {uid}: {first.path.name} and {other.path.name} differ"
            )
        if not np.allclose(other.pixel_spacing, first.pixel_spacing, rtol=1e-4):
            raise InputError(
                source, f"mixed pixel spacing in series {uid}: {first.path.name} and {other.path.name} differ"
            )
    if len(slices) < 2:
        raise InputError(source, f"series {uid} has a single slice ({first.path.name}); a volume needs at least 2")
    row, column = _cosines(first)
    normal = np.cross(row, column)
    origins = np.array([s.position for s in slices])
    along = origins @ normal
    order = np.argsort(along, kind="stable")
    _check_shear(source, origins[order], normal, min(first.pixel_spacing))
    return _Stack(
        slices=[slices[i] for i in order],
        positions=along[order],
        direction=np.column_stack([row, column, normal]),
        pixel_spacing=(first.pixel_spacing[1], first.pixel_spacing[0]),
    )


def _parse_slice(header: _Header) -> _Slice:
    """Geometry of a one-frame, one-sample image; InputError naming the file for anything amiss."""
    ds = header.ds
    if int(ds.get("NumberOfFrames", 1) or 1) > 1:
        raise InputError(
            header.path,
            f"multi-frame (enhanced) DICOM with {ds.NumberOfFrames} frames is not supported; "
            "convert it to single-frame files or NIfTI (e.g. with dcm2niix)",
        )
    missing = [tag for tag in _REQUIRED_TAGS if _is_empty(ds.get(tag))]
    if missing:
        raise InputError(
            header.path, f"DICOM slice lacks {', '.join(missing)} (not a cross-sectional image, or a damaged header)"
        )
    if int(ds.get("SamplesPerPixel", 1) or 1) != 1:
        raise InputError(header.path, f"colour DICOM (SamplesPerPixel={ds.SamplesPerPixel}) is not supported")
    return _Slice(
        path=header.path,
        ds=ds,
        rows=int(ds.Rows),
        columns=int(ds.Columns),
        pixel_spacing=tuple(_numbers(header, "PixelSpacing", 2)),
        position=_numbers(header, "ImagePositionPatient", 3),
        orientation=_numbers(header, "ImageOrientationPatient", 6),
    )


def _numbers(header: _Header, tag: str, count: int) -> np.ndarray:
    """A multi-valued decimal tag as ``count`` finite floats, or InputError naming the file."""
    value = header.ds.get(tag)
    values = list(value) if isinstance(value, (list, tuple, MultiValue)) else [value]
    try:
        numbers = np.array([float(v) for v in values], dtype=float)
    except (TypeError, ValueError):
        raise InputError(header.path, f"{tag} is not numeric: {values}") from None
    if numbers.shape != (count,) or not np.all(np.isfinite(numbers)):
        raise InputError(header.path, f"{tag} must be {count} finite numbers, got {values}")
    return numbers


def _cosines(first: _Slice) -> tuple[np.ndarray, np.ndarray]:
    """Unit row and column cosines; InputError unless they are (nearly) unit length and orthogonal."""
    row, column = first.orientation[:3], first.orientation[3:]
    lengths = np.linalg.norm(row), np.linalg.norm(column)
    if min(lengths) < 0.99 or max(lengths) > 1.01 or abs(float(row @ column)) > 1e-3:
        cosines = " ".join(f"{v:g}" for v in first.orientation)
        raise InputError(first.path, f"ImageOrientationPatient ({cosines}) is not two orthogonal unit vectors")
    return row / lengths[0], column / lengths[1]


def _check_shear(source: Path, origins: np.ndarray, normal: np.ndarray, pixel_size: float) -> None:
    """Slice origins must line up along the normal (no gantry tilt) within a quarter pixel."""
    offsets = origins - origins[0]
    sideways = offsets - np.outer(offsets @ normal, normal)
    drift = float(np.linalg.norm(sideways, axis=1).max())
    if drift > 0.25 * pixel_size:
        raise InputError(
            source,
            f"slice positions drift {drift:.2f} mm sideways from the slice normal (gantry tilt?); "
            "sheared slice stacks are not supported",
        )


def _slice_step(source: Path, stack: _Stack, resample: bool) -> tuple[float, bool]:
    """(slice spacing in mm, needs resampling?).

    Evenly spaced slices (every gap within GAP_TOLERANCE of the median): their mean gap, False.
    Uneven ones with ``resample``: the median gap, True. Raises InputError for duplicate
    positions, or uneven gaps without ``resample``.
    """
    gaps = np.diff(stack.positions)
    median = float(np.median(gaps))
    duplicate_tolerance = max(1e-3, GAP_TOLERANCE * median)
    if median <= duplicate_tolerance or gaps.min() <= duplicate_tolerance:
        i = int(np.argmin(gaps))
        pairs = int((gaps <= duplicate_tolerance).sum())
        raise InputError(
            source,
            f"two slices at one position ({stack.slices[i].path.name} and {stack.slices[i + 1].path.name}, "
            f"{stack.positions[i]:.2f} mm along the normal; {pairs} such pair{'s' if pairs != 1 else ''}): "
            "a series mixing acquisitions or echoes, or a copied file? remove the extra files",
        )
    if np.abs(gaps - median).max() <= max(GAP_TOLERANCE * median, 1e-3):
        return float(gaps.mean()), False
    if resample:
        return median, True
    missing = int(np.maximum(np.rint(gaps / median) - 1, 0).sum())
    widest = int(np.argmax(gaps))
    hint = f"{missing} slice{'s' if missing != 1 else ''} missing? " if missing else ""
    raise InputError(
        source,
        f"non-uniform slice spacing ({gaps.min():.2f}-{gaps.max():.2f} mm; {hint}largest gap between "
        f"{stack.slices[widest].path.name} and {stack.slices[widest + 1].path.name}); pass resample=True "
        "(CLI --resample) to resample to uniform spacing",
    )


def _read_pixels(slices: list[_Slice]) -> tuple[np.ndarray, str, str, list[tuple[int, str]]]:
    """Stack of rescaled slices (float32 (z, y, x)), a note on the rescale, the units, and the slices
    left out of the stack because their file is damaged, as (index, problem)."""
    volume = np.empty((len(slices), slices[0].rows, slices[0].columns), dtype=np.float32)
    rescales = set()
    damaged: list[tuple[int, str]] = []
    for k, item in enumerate(slices):
        try:
            ds = _read_full(item.path)
            pixels = _pixels(item.path, ds, volume.shape[1:])
        except InputError as err:
            damaged.append((k, err.problem))
            continue
        slope = _rescale(item.path, ds, "RescaleSlope", 1.0)
        intercept = _rescale(item.path, ds, "RescaleIntercept", 0.0)
        rescales.add((slope, intercept))
        volume[k] = pixels.astype(np.float64) * slope + intercept
    if damaged:
        volume = np.delete(volume, [k for k, _ in damaged], axis=0)
    units = _units(slices[0].ds)
    if len(rescales) == 1:
        slope, intercept = rescales.pop()
        sign = "-" if intercept < 0 else "+"
        note = f"values = stored * {slope:g} {sign} {abs(intercept):g} (RescaleSlope, RescaleIntercept)"
    else:
        note = f"per-slice RescaleSlope/RescaleIntercept applied ({len(rescales)} different pairs)"
    return volume, note + (f" -> {units}" if units else ""), units, damaged


def _pixels(path: Path, ds: Dataset, shape: tuple[int, ...]) -> np.ndarray:
    """A slice's stored pixel values, of ``shape`` (Rows, Columns); InputError naming the file otherwise."""
    try:
        pixels = ds.pixel_array
    except Exception as err:  # pydicom raises many types for bad pixel data
        raise InputError(path, f"cannot decode the pixel data: {_one_line(err)}") from None
    if pixels.shape != shape:
        raise InputError(path, f"pixel data has shape {pixels.shape}, expected {shape} (Rows, Columns)")
    return pixels


def _without(source: Path, stack: _Stack, dropped: list[int]) -> _Stack:
    """``stack`` less the slices at the ``dropped`` indices; InputError when fewer than 2 remain."""
    keep = [k for k in range(len(stack.slices)) if k not in set(dropped)]
    if len(keep) < 2:
        raise InputError(source, f"only {len(keep)} readable slice{'s' if len(keep) != 1 else ''} in the series; "
                         "a volume needs at least 2")
    return _Stack([stack.slices[k] for k in keep], stack.positions[keep], stack.direction, stack.pixel_spacing)


def _filled_slices(stack: _Stack, step: float) -> list[str]:
    """Which slices of the resampled stack (index ``k`` at ``positions[0] + k * step``) lie in a gap of
    at least FILLED_GAP steps, i.e. stand where no slice was: "slices 40-41 between A.dcm and B.dcm (4.5 mm gap)"."""
    filled = []
    for i, gap in enumerate(np.diff(stack.positions)):
        if gap < FILLED_GAP * step:
            continue
        start = stack.positions[i] - stack.positions[0]
        first, last = int(np.floor(start / step + 0.5)) + 1, int(np.ceil((start + gap) / step - 0.5)) - 1
        if last < first:
            continue
        which = f"slice {first}" if first == last else f"slices {first}-{last}"
        filled.append(f"{which} between {stack.slices[i].path.name} and {stack.slices[i + 1].path.name} "
                      f"({gap:.3g} mm gap)")
    return filled


def _read_full(file: Path) -> Dataset:
    """A whole DICOM file, pixel data included; a damaged file raises InputError."""
    try:
        return pydicom.dcmread(file, force=False)
    except Exception as err:  # pydicom raises many types for damaged files
        raise InputError(file, f"truncated or corrupt DICOM file: {_one_line(err)}") from None


def _units(ds: Dataset) -> str:
    """"HU" for CT with a rescale to Hounsfield units; else the RescaleType, if any."""
    rescale_type = str(ds.get("RescaleType", "") or "").strip()
    if ds.get("Modality") == "CT" and "RescaleIntercept" in ds and rescale_type in ("", "HU"):
        return "HU"
    return "" if rescale_type.upper() in ("", "US") else rescale_type


def _is_empty(value: object) -> bool:
    """True for an absent or empty DICOM value (None, "", an empty multi-value)."""
    return value is None or value == "" or (hasattr(value, "__len__") and len(value) == 0)


def _rescale(path: Path, ds: Dataset, keyword: str, default: float) -> float:
    """RescaleSlope or RescaleIntercept as a float (``default`` when absent)."""
    value = ds.get(keyword)
    if _is_empty(value):
        return default
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = float("nan")
    if not np.isfinite(number):
        raise InputError(path, f"{keyword} is not a number: {value}")
    return number


def _resample_slices(volume: np.ndarray, positions: np.ndarray, step: float) -> np.ndarray:
    """Linear interpolation of slices at increasing ``positions`` (mm) onto positions[0] + k * step."""
    count = int(np.floor((positions[-1] - positions[0]) / step + 1e-6)) + 1
    targets = positions[0] + step * np.arange(count)
    upper = np.clip(np.searchsorted(positions, targets, side="right"), 1, len(positions) - 1)
    out = np.empty((count,) + volume.shape[1:], dtype=np.float32)
    for k, (hi, target) in enumerate(zip(upper, targets)):
        t = (target - positions[hi - 1]) / (positions[hi] - positions[hi - 1])
        out[k] = (1.0 - t) * volume[hi - 1] + t * volume[hi]
    return out


def _one_line(err: BaseException) -> str:
    """An exception's message on one line, at most 240 characters."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= 240 else text[:237] + "..."
