"""What a loader hands over: voxels plus geometry, checked once, before any rendering.

Conventions (docs/conventions.md): arrays are indexed (z, y, x) = (k, j, i); world coordinates
are millimetres in LPS, as in DICOM and ITK. A voxel's value sits at its centre:

    world(i, j, k) = origin + direction @ (spacing * [i, j, k])

with ``spacing`` given as (x, y, z) and ``direction`` a 3x3 matrix whose *columns* are the
world directions of the i, j and k index axes (ITK's GetDirection(), reshaped row-major).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from volsr_core.errors import InputError


@dataclass(frozen=True)
class SeriesInfo:
    """One DICOM series found in a folder (``volsr info`` lists them)."""

    series_uid: str
    description: str
    modality: str
    n_files: int
    rows: int
    columns: int


@dataclass
class VolumeRecord:
    """A scalar volume as read from disk: float32 voxels (z, y, x) and LPS geometry in mm.

    Construction validates: 3-D, at least 2 voxels along every axis, finite values,
    positive spacing, an orthonormal direction matrix. Problems raise
    :class:`~volsr_core.errors.InputError` naming ``source``.
    """

    array: np.ndarray
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: np.ndarray = field(default_factory=lambda: np.eye(3))
    modality: str = "OT"
    units: str = ""
    source: str = "<memory>"
    series: list[SeriesInfo] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        arr = np.asarray(self.array)
        if arr.ndim != 3:
            raise InputError(self.source, f"expected a 3-D volume, got a {arr.ndim}-D image of shape {arr.shape}")
        if min(arr.shape) < 2:
            raise InputError(self.source, f"needs at least 2 voxels along every axis, got (z, y, x) = {arr.shape}")
        if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
            raise InputError(self.source, f"unsupported voxel type {arr.dtype}")
        arr = np.ascontiguousarray(arr, dtype=np.float32)
        finite = np.isfinite(arr)
        if not finite.all():
            raise InputError(self.source, f"contains {arr.size - int(finite.sum())} NaN or Inf voxel values")
        self.array = arr
        spacing = np.asarray(self.spacing, dtype=float).reshape(-1)
        if spacing.shape != (3,) or not np.all(np.isfinite(spacing)) or np.any(spacing <= 0):
            raise InputError(self.source, f"spacing must be three positive numbers, got {self.spacing}")
        self.spacing = tuple(float(s) for s in spacing)
        origin = np.asarray(self.origin, dtype=float).reshape(-1)
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise InputError(self.source, f"origin must be three finite numbers, got {self.origin}")
        self.origin = tuple(float(o) for o in origin)
        direction = np.asarray(self.direction, dtype=float).reshape(3, 3)
        if not np.allclose(direction.T @ direction, np.eye(3), atol=1e-3):
            raise InputError(self.source, "direction cosines are not orthonormal")
        self.direction = direction

    @property
    def shape_xyz(self) -> tuple[int, int, int]:
        """Voxel counts along (x, y, z), the order DICOM, ITK and VTK print."""
        z, y, x = self.array.shape
        return (x, y, z)
