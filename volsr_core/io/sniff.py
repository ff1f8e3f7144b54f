"""Content sniffing: does a file hold what its name says, and is its voxel data all there?

Checked before a file reaches SimpleITK, pydicom or VTK, so that a wrong or damaged file gets a
one-line :class:`~volsr_core.errors.InputError` instead of a library's multi-line message (or, for
a truncated NIfTI file, no message at all: ITK silently fills the missing voxels with zeros).

Format keys used throughout ``volsr_core.io``: ``"dicom"``, ``"nrrd"``, ``"nifti"``,
``"nifti_gz"``, ``"metaimage"``, ``"vti"``.
"""
from __future__ import annotations

import gzip
import os
import re
import struct
import zlib
from pathlib import Path

from volsr_core.errors import InputError

FORMAT_NAMES = {
    "dicom": "DICOM",
    "nrrd": "NRRD",
    "nifti": "NIfTI",
    "nifti_gz": "gzip-compressed NIfTI",
    "metaimage": "MetaImage",
    "vti": "VTK XML image data (.vti)",
}

#: File extension (lower case) -> format key.
FORMAT_BY_EXTENSION = {
    ".dcm": "dicom",
    ".nrrd": "nrrd",
    ".nhdr": "nrrd",
    ".nii": "nifti",
    ".nii.gz": "nifti_gz",
    ".mha": "metaimage",
    ".mhd": "metaimage",
    ".vti": "vti",
}

_HEAD_BYTES = 4096
_NIFTI_HEADER_BYTES = 540  # NIfTI-2 header size; NIfTI-1 needs 348
_METAIMAGE_KEY = re.compile(rb"^[ \t]*(ObjectType|NDims|DimSize|ElementType|ElementDataFile)[ \t]*=", re.MULTILINE)
_VTK_FILE_TYPE = re.compile(rb'<VTKFile\b[^>]*?\btype\s*=\s*"([^"]*)"')
_METAIMAGE_TYPE_BYTES = {
    "MET_CHAR": 1, "MET_UCHAR": 1, "MET_SHORT": 2, "MET_USHORT": 2, "MET_INT": 4, "MET_UINT": 4,
    "MET_LONG": 4, "MET_ULONG": 4, "MET_LONG_LONG": 8, "MET_ULONG_LONG": 8, "MET_FLOAT": 4, "MET_DOUBLE": 8,
}


def extension_of(path: str | os.PathLike) -> str:
    """Lower-case extension of ``path``, with ``.nii.gz`` kept whole (``""`` when there is none)."""
    name = Path(path).name.lower()
    if name.endswith(".nii.gz"):
        return ".nii.gz"
    return Path(name).suffix


def read_head(path: str | os.PathLike, size: int = _HEAD_BYTES) -> bytes:
    """First ``size`` bytes of a file; an unreadable file raises InputError."""
    try:
        with open(path, "rb") as stream:
            return stream.read(size)
    except OSError as err:
        raise InputError(path, f"cannot read the file: {err.strerror or err}") from None


def is_dicom_file(path: str | os.PathLike) -> bool:
    """True when the file carries the DICOM Part 10 magic ``DICM`` at byte 128."""
    return read_head(path, 132)[128:132] == b"DICM"


def describe_start(head: bytes) -> str:
    """A short, one-line description of how a file starts: quoted text, or hex bytes."""
    if not head:
        return "the file is empty"
    sample = head[:16]
    if all(32 <= b < 127 or b in b"\t\r\n" for b in sample):
        text = sample.decode("ascii").replace("\r", "\\r").replace("\n", "\\n").replace("\t", "\\t")
        return f'starts with "{text}"'
    return "starts with bytes " + " ".join(f"{b:02x}" for b in sample[:8])


def check_content(path: str | os.PathLike, fmt: str) -> None:
    """Raise InputError unless the file's first bytes match format ``fmt`` (a key of FORMAT_NAMES)."""
    head = read_head(path)
    if fmt == "nifti_gz":
        if head[:2] != b"\x1f\x8b":
            raise _mismatch(path, fmt, describe_start(head))
        inner = _gunzip_start(path, _NIFTI_HEADER_BYTES)
        if _nifti_endian(inner) is None:
            raise _mismatch(path, fmt, "gzip data that " + describe_start(inner))
        return
    if not _looks_like(fmt, head):
        raise _mismatch(path, fmt, describe_start(head))
    if fmt == "vti":
        match = _VTK_FILE_TYPE.search(head)
        if match and match.group(1) != b"ImageData":
            kind = match.group(1).decode("ascii", "replace")
            raise InputError(path, f'is a VTK XML "{kind}" file, not "ImageData"; only image data can be read')


def _looks_like(fmt: str, head: bytes) -> bool:
    """Magic-byte test of an uncompressed file's first bytes."""
    if fmt == "dicom":
        return head[128:132] == b"DICM"
    if fmt == "nrrd":
        return head.startswith(b"NRRD000")
    if fmt == "nifti":
        return _nifti_endian(head) is not None
    if fmt == "metaimage":
        return _METAIMAGE_KEY.search(head) is not None
    if fmt == "vti":
        return head.lstrip(b"\xef\xbb\xbf \t\r\n").startswith((b"<?xml", b"<VTKFile"))
    raise ValueError(f"unknown format key {fmt!r}")


def _mismatch(path: str | os.PathLike, fmt: str, description: str) -> InputError:
    if fmt == "nifti" and description.startswith("starts with bytes 1f 8b"):
        description += ": gzip data, name it .nii.gz"
    return InputError(path, f"content does not look like a {FORMAT_NAMES[fmt]} file ({description})")


def _gunzip_start(path: str | os.PathLike, size: int) -> bytes:
    """First ``size`` decompressed bytes of a gzip file."""
    try:
        with gzip.open(path, "rb") as stream:
            return stream.read(size)
    except (OSError, EOFError, zlib.error) as err:
        raise InputError(path, f"corrupt gzip data ({err})") from None


def _nifti_endian(header: bytes) -> str | None:
    """``"<"`` or ``">"`` when ``header`` starts with a NIfTI-1 (348) or NIfTI-2 (540) sizeof_hdr."""
    if len(header) < 4:
        return None
    for endian in "<>":
        if struct.unpack(endian + "i", header[:4])[0] in (348, 540):
            return endian
    return None


def check_nifti_complete(path: str | os.PathLike, fmt: str) -> None:
    """Raise InputError when a NIfTI file holds fewer bytes than its header announces.

    ITK reads a truncated NIfTI file without complaint and zero-fills the rest, so the length is
    checked here. For ``.nii.gz`` this decompresses the whole stream once (about 0.3 s per 100 MB).
    """
    if fmt == "nifti":
        header, length = read_head(path, _NIFTI_HEADER_BYTES), os.path.getsize(path)
    else:
        header, length = _gunzip_header_and_length(path)
    expected = _nifti_expected_length(header)
    if expected is not None and length < expected:
        where = "decompresses to" if fmt == "nifti_gz" else "holds"
        raise InputError(path, f"truncated: the NIfTI header announces {expected} bytes, the file {where} {length}")


def _gunzip_header_and_length(path: str | os.PathLike) -> tuple[bytes, int]:
    """First NIfTI-2-header's worth of decompressed bytes and the total decompressed length."""
    try:
        with gzip.open(path, "rb") as stream:
            header = stream.read(_NIFTI_HEADER_BYTES)
            length = len(header)
            while chunk := stream.read(1 << 22):
                length += len(chunk)
    except (OSError, EOFError, zlib.error) as err:
        raise InputError(path, f"truncated or corrupt gzip data ({err})") from None
    return header, length


def _nifti_expected_length(header: bytes) -> int | None:
    """vox_offset + voxel bytes from a NIfTI-1/-2 header; None when the header is too odd to tell."""
    endian = _nifti_endian(header)
    if endian is None:
        return None
    header_size = struct.unpack(endian + "i", header[:4])[0]
    if len(header) < header_size:
        return header_size
    if header_size == 348:
        dims = struct.unpack(endian + "8h", header[40:56])
        bitpix = struct.unpack(endian + "h", header[72:74])[0]
        vox_offset = int(struct.unpack(endian + "f", header[108:112])[0])
    else:
        bitpix = struct.unpack(endian + "h", header[14:16])[0]
        dims = struct.unpack(endian + "8q", header[16:80])
        vox_offset = struct.unpack(endian + "q", header[168:176])[0]
    ndim = dims[0]
    if not 1 <= ndim <= 7 or bitpix <= 0 or any(d < 1 for d in dims[1 : ndim + 1]):
        return None
    voxels = 1
    for d in dims[1 : ndim + 1]:
        voxels *= d
    return max(vox_offset, 0) + voxels * bitpix // 8


def check_detached_data(path: str | os.PathLike, fmt: str) -> None:
    """For a MetaImage or NRRD header naming a separate data file: check that file is there and,
    when uncompressed MetaImage, long enough. Raises InputError naming what is missing."""
    if fmt == "metaimage":
        _check_metaimage_data(Path(path))
    elif fmt == "nrrd":
        fields = _header_fields(read_head(Path(path), 1 << 16), ":")
        data_file = fields.get("data file") or fields.get("datafile")
        if data_file:
            _require_data_file(Path(path), data_file, "the NRRD 'data file' field")


def _check_metaimage_data(path: Path) -> None:
    raw = read_head(path, 1 << 16)
    fields = _header_fields(raw, "=")
    data_file = fields.get("ElementDataFile")
    if data_file is None:
        raise InputError(path, "MetaImage header has no ElementDataFile line")
    if data_file.upper() == "LOCAL":
        line_end = raw.find(b"\n", raw.find(b"ElementDataFile"))
        data_path, available = path, os.path.getsize(path) - (line_end + 1)
    else:
        data_path = _require_data_file(path, data_file, "ElementDataFile")
        if data_path is None:
            return
        available = os.path.getsize(data_path)
    if fields.get("CompressedData", "False").lower() == "true":
        return
    expected = _metaimage_data_bytes(fields)
    if expected is not None and available < expected:
        raise InputError(
            data_path, f"truncated voxel data: {available} bytes where the MetaImage header needs {expected}"
        )


def _metaimage_data_bytes(fields: dict[str, str]) -> int | None:
    """Bytes of uncompressed voxel data a MetaImage header announces (None when it cannot tell)."""
    item = _METAIMAGE_TYPE_BYTES.get(fields.get("ElementType", ""))
    try:
        dims = [int(d) for d in fields.get("DimSize", "").split()]
        channels = int(fields.get("ElementNumberOfChannels", "1"))
        header_size = max(int(fields.get("HeaderSize", "0")), 0)
    except ValueError:
        return None
    if item is None or not dims:
        return None
    total = item * channels
    for d in dims:
        total *= d
    return header_size + total


def _require_data_file(header_path: Path, data_file: str, field_name: str) -> Path | None:
    """Path of a single detached data file (relative to the header's folder), which must exist.

    None for file lists and patterns (``LIST``, ``%03d``, several names), which are left to ITK.
    """
    if data_file.upper() == "LIST" or "%" in data_file or len(data_file.split()) != 1:
        return None
    data_path = header_path.parent / data_file
    if not data_path.is_file():
        raise InputError(
            header_path, f"data file '{data_file}' named by {field_name} is missing (looked for {data_path})"
        )
    return data_path


def _header_fields(raw: bytes, separator: str) -> dict[str, str]:
    """``key <separator> value`` lines of a text header (stops at the first blank line)."""
    fields: dict[str, str] = {}
    for line in raw.decode("latin-1").splitlines():
        if not line.strip():
            break
        key, sep, value = line.partition(separator)
        if sep:
            fields.setdefault(key.strip(), value.strip())
        if key.strip() == "ElementDataFile":  # the last MetaImage header line; voxel bytes may follow
            break
    return fields
