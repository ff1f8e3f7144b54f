"""``read_volume``: one entry point for every supported volume file, dispatched on what the path is.

* a folder, a ``.dcm`` file, or a file without extension (or with an unknown one) that carries
  the DICOM magic -> :func:`volsr_core.io.dicom.read_dicom`;
* ``.nrrd``/``.nhdr``, ``.nii``, ``.nii.gz``, ``.mha``/``.mhd`` -> SimpleITK, which already
  converts NIfTI's RAS to LPS;
* ``.vti`` -> VTK's XML image data reader (VTK is optional; imported only here).

Every file's first bytes are checked against its extension first (:mod:`volsr_core.io.sniff`),
and every failure is an :class:`~volsr_core.errors.InputError` with a one-line message.
"""
from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import SimpleITK as sitk

from volsr_core.errors import InputError
from volsr_core.io.dicom import read_dicom
from volsr_core.io.record import VolumeRecord
from volsr_core.io.sniff import (
    FORMAT_BY_EXTENSION,
    FORMAT_NAMES,
    check_content,
    check_detached_data,
    check_nifti_complete,
    describe_start,
    extension_of,
    is_dicom_file,
    read_head,
)

#: File extensions read_volume accepts (besides DICOM folders and extension-less DICOM files).
SUPPORTED_EXTENSIONS: tuple[str, ...] = tuple(FORMAT_BY_EXTENSION)

_SUPPORTED_TEXT = (
    "supported: a DICOM folder or file (.dcm or no extension), "
    + ", ".join(ext for ext in SUPPORTED_EXTENSIONS if ext != ".dcm")
)
_SITK_IMAGE_IO = {
    "nrrd": "NrrdImageIO", "nifti": "NiftiImageIO", "nifti_gz": "NiftiImageIO", "metaimage": "MetaImageIO",
}
_METAIMAGE_MODALITY = {"MET_MOD_CT": "CT", "MET_MOD_MR": "MR", "MET_MOD_NM": "NM", "MET_MOD_US": "US"}
_VTK_NEEDED = "reading .vti needs VTK: pip install 'volsr[vtk]'"


def read_volume(path: str | os.PathLike, series_uid: str | None = None, resample: bool = False) -> VolumeRecord:
    """Read a volume file or DICOM folder as a :class:`VolumeRecord`.

    The record holds float32 voxels indexed (z, y, x), spacing (x, y, z) in mm, the LPS world
    position of voxel (0, 0, 0)'s centre as origin, and a direction matrix whose columns are
    the world directions of the i, j, k index axes.

    ``series_uid`` picks a DICOM series (default: the one with the most files); ``resample``
    lets a DICOM stack with uneven slice gaps be interpolated to its median gap instead of
    refused. Raises InputError (one line, naming the file) for anything it cannot read.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "no such file or folder")
    fmt = "dicom" if path.is_dir() else _file_format(path)
    if fmt == "dicom":
        return read_dicom(path, series_uid=series_uid, resample=resample)
    if series_uid is not None:
        raise InputError(path, "a series UID (CLI --series) applies only to DICOM input")
    check_content(path, fmt)
    if fmt == "vti":
        return _read_vti(path)
    return _read_with_sitk(path, fmt)


def _file_format(path: Path) -> str:
    """Format key for a file: by extension; unknown or no extension -> DICOM if it has the magic."""
    ext = extension_of(path)
    if ext in FORMAT_BY_EXTENSION:
        return FORMAT_BY_EXTENSION[ext]
    if is_dicom_file(path):
        return "dicom"
    if not ext:
        start = describe_start(read_head(path))
        raise InputError(path, f"no file extension, and not a DICOM file ({start}); {_SUPPORTED_TEXT}")
    raise InputError(path, f"unsupported file type '{ext}'; {_SUPPORTED_TEXT}")


def _read_with_sitk(path: Path, fmt: str) -> VolumeRecord:
    """NRRD, NIfTI or MetaImage through SimpleITK (geometry already LPS)."""
    if fmt in ("nifti", "nifti_gz"):
        check_nifti_complete(path, fmt)
    else:
        check_detached_data(path, fmt)
    reader = sitk.ImageFileReader()
    reader.SetImageIO(_SITK_IMAGE_IO[fmt])
    reader.SetFileName(str(path))
    try:
        image = reader.Execute()
    except RuntimeError as err:
        raise InputError(path, f"SimpleITK cannot read it: {_sitk_message(err)}") from None
    if image.GetDimension() != 3:
        size = " x ".join(str(n) for n in image.GetSize())
        raise InputError(path, f"expected a 3-D volume, got a {image.GetDimension()}-D image of {size} voxels")
    array = sitk.GetArrayFromImage(image)
    notes = [f"{FORMAT_NAMES[fmt]} file read with SimpleITK; stored voxel type: {image.GetPixelIDTypeAsString()}"]
    components = image.GetNumberOfComponentsPerPixel()
    if components > 1:
        array = array[..., 0]
        notes.append(f"took component 1 of {components} per voxel")
    if fmt in ("nifti", "nifti_gz"):
        notes.append("NIfTI RAS+ world coordinates converted to LPS by SimpleITK")
    modality = "OT"
    if fmt == "metaimage" and image.HasMetaDataKey("Modality"):
        modality = _METAIMAGE_MODALITY.get(image.GetMetaData("Modality").strip(), "OT")
    return VolumeRecord(
        array=array,
        spacing=image.GetSpacing(),
        origin=image.GetOrigin(),
        direction=np.array(image.GetDirection(), dtype=float).reshape(3, 3),
        modality=modality,
        units="",
        source=str(path),
        notes=notes,
    )


def _sitk_message(err: RuntimeError) -> str:
    """The useful part of a SimpleITK/ITK exception, on one line.

    Drops the "Exception thrown in SimpleITK ..." line and source locations, strips
    "ITK ERROR: Class(0x...):" prefixes, and of teem's "[nrrd] function:" trace keeps the last line.
    """
    kept: list[str] = []
    trace_tail = ""
    for line in str(err).splitlines():
        line = line.strip()
        if not line or line.startswith("Exception thrown in SimpleITK"):
            continue
        line = re.sub(r"^(ITK ERROR|sitk::ERROR):\s*(\w+\(0x[0-9a-fA-F]+\):\s*)?", "", line)
        if line.startswith("["):
            trace_tail = re.sub(r"^\[\w+\]\s*\w+:\s*", "", line)
        else:
            kept.append(line)
    text = " ".join(kept + [trace_tail]).strip() or "unknown error"
    return text if len(text) <= 300 else text[:297] + "..."


def _read_vti(path: Path) -> VolumeRecord:
    """VTK XML image data: the active point scalars (component 1) and the image geometry."""
    try:
        from volsr_core._vtk import vtk_to_numpy, vtkXMLImageDataReader
    except ImportError:
        raise InputError(path, _VTK_NEEDED) from None
    reader = vtkXMLImageDataReader()
    reader.SetFileName(str(path))
    with _vtk_errors() as errors:
        reader.Update()
    if errors:
        raise InputError(path, f"VTK cannot read it: {errors[0]}")
    image = reader.GetOutput()
    scalars, notes = _vti_scalars(path, image)
    values = np.array(vtk_to_numpy(scalars))  # copy: the VTK array dies with the reader
    if values.ndim == 2:
        notes.append(f"took component 1 of {values.shape[1]} of point array '{scalars.GetName()}'")
        values = values[:, 0]
    nx, ny, nz = image.GetDimensions()
    matrix = image.GetDirectionMatrix()
    direction = np.array([[matrix.GetElement(r, c) for c in range(3)] for r in range(3)])
    spacing = np.array(image.GetSpacing())
    first_index = np.array(image.GetExtent()[::2], dtype=float)  # extents need not start at 0
    origin = np.array(image.GetOrigin()) + direction @ (spacing * first_index)
    notes.append("VTK image data has no patient coordinate system; its world coordinates are taken as LPS mm")
    return VolumeRecord(
        array=values.reshape(nz, ny, nx),
        spacing=tuple(spacing),
        origin=tuple(origin),
        direction=direction,
        modality="OT",
        units="",
        source=str(path),
        notes=notes,
    )


def _vti_scalars(path: Path, image: object) -> tuple[object, list[str]]:
    """The active point scalars, else the first numeric point array (noted); InputError if none."""
    point_data = image.GetPointData()
    scalars = point_data.GetScalars()
    if scalars is not None:
        return scalars, []
    for i in range(point_data.GetNumberOfArrays()):
        array = point_data.GetArray(i)  # None for non-numeric arrays
        if array is not None:
            return array, [f"no active point scalars; used point array '{array.GetName()}'"]
    where = " (it has only cell data)" if image.GetCellData().GetNumberOfArrays() else ""
    raise InputError(path, f"no point scalars to read{where}")


@contextlib.contextmanager
def _vtk_errors() -> Iterator[list[str]]:
    """Collect VTK error messages instead of printing them; the list is filled on exit.

    Temporarily swaps VTK's global output window for a string window and mutes the VTK
    logger's stderr output, restoring both afterwards (not thread-safe, as VTK's globals are not).
    """
    from volsr_core._vtk import vtkLogger, vtkOutputWindow, vtkStringOutputWindow

    previous_window = vtkOutputWindow.GetInstance()
    previous_verbosity = vtkLogger.GetCurrentVerbosityCutoff()
    capture = vtkStringOutputWindow()
    vtkOutputWindow.SetInstance(capture)
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_OFF)
    errors: list[str] = []
    try:
        yield errors
    finally:
        vtkOutputWindow.SetInstance(previous_window)
        vtkLogger.SetStderrVerbosity(previous_verbosity)
        errors += re.findall(r"ERROR: In [^\n]*\n(?:\w+ \(0x[0-9a-fA-F]+\): )?([^\n]+)", capture.GetOutput())
